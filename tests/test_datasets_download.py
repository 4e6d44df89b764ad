"""slam2d datasets: the catalogue matches the data; download from a local HTTP server (no internet)."""

from __future__ import annotations

import hashlib
import json
import re
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from typer.testing import CliRunner

from slam2d.cli import app
from slam2d.datasets import catalog
from slam2d.datasets.catalog import DataFile
from slam2d.datasets.download import download, select, sha256_of
from slam2d.errors import InputError

PAYLOAD = bytes(range(256)) * 40  # 10240 bytes
NAME = "testdata/small.bin"


class _Handler(BaseHTTPRequestHandler):
    """Serves PAYLOAD at /small.bin, honouring ``Range: bytes=N-``; records each request's Range and bytes sent."""

    log: list[tuple[str | None, int]] = []

    def do_GET(self):
        if self.path != "/small.bin":
            self.send_error(404)
            return
        wanted = self.headers.get("Range")
        start = int(re.fullmatch(r"bytes=(\d+)-", wanted).group(1)) if wanted and self.server.ranges else 0
        body = PAYLOAD[start:]
        self.send_response(206 if start else 200)
        if start:
            self.send_header("Content-Range", f"bytes {start}-{len(PAYLOAD) - 1}/{len(PAYLOAD)}")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.server.log.append((wanted, len(body)))  # before the body: the client may return as soon as it has it
        self.wfile.write(body)

    def log_message(self, *args):
        pass


@pytest.fixture
def server():
    httpd = ThreadingHTTPServer(("127.0.0.1", 0), _Handler)
    httpd.log, httpd.ranges = [], True
    thread = threading.Thread(target=httpd.serve_forever, daemon=True)
    thread.start()
    yield httpd
    httpd.shutdown()
    httpd.server_close()


def _entry(url: str, sha256: str | None = None) -> DataFile:
    return DataFile(NAME, len(PAYLOAD), sha256 or hashlib.sha256(PAYLOAD).hexdigest(), url,
                    "CC0-1.0", "download tests", "made by the test")


@pytest.fixture
def served(server, monkeypatch):
    """The catalogue is one file, served by ``server``."""
    monkeypatch.setattr(catalog, "CATALOGUE", (_entry(f"http://127.0.0.1:{server.server_port}/small.bin"),))
    return server


def test_download_verifies_and_writes(served, tmp_path):
    (path,) = download([NAME], tmp_path, quiet=True)
    assert path == tmp_path / NAME and path.read_bytes() == PAYLOAD
    assert not (tmp_path / (NAME + ".part")).exists()
    assert served.log == [(None, len(PAYLOAD))]
    download(["all"], tmp_path, quiet=True)  # verified already: not fetched again
    assert len(served.log) == 1


def test_resume_requests_range_and_appends(served, tmp_path):
    part = tmp_path / (NAME + ".part")
    part.parent.mkdir(parents=True)
    part.write_bytes(PAYLOAD[:3000])
    (path,) = download(["testdata"], tmp_path, quiet=True)
    assert served.log == [("bytes=3000-", len(PAYLOAD) - 3000)]  # only the missing bytes travelled
    assert path.read_bytes() == PAYLOAD and not part.exists()


def test_server_ignoring_range_restarts_from_zero(served, tmp_path):
    served.ranges = False
    part = tmp_path / (NAME + ".part")
    part.parent.mkdir(parents=True)
    part.write_bytes(b"x" * 3000)  # would corrupt the file if appended to
    (path,) = download([NAME], tmp_path, quiet=True)
    assert path.read_bytes() == PAYLOAD


def test_wrong_checksum_fails_and_leaves_no_file(server, monkeypatch, tmp_path):
    wrong = hashlib.sha256(b"other bytes").hexdigest()
    monkeypatch.setattr(catalog, "CATALOGUE", (_entry(f"http://127.0.0.1:{server.server_port}/small.bin", wrong),))
    with pytest.raises(InputError) as err:
        download([NAME], tmp_path, quiet=True)
    message = str(err.value)
    assert "\n" not in message and NAME in message
    assert wrong in message and hashlib.sha256(PAYLOAD).hexdigest() in message
    assert not (tmp_path / NAME).exists() and not (tmp_path / (NAME + ".part")).exists()
    assert not (tmp_path / NAME).parent.exists()  # no empty folder left behind


def _closed_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def test_unreachable_url_is_one_line_error(monkeypatch, tmp_path):
    monkeypatch.setattr(catalog, "CATALOGUE", (_entry(f"http://127.0.0.1:{_closed_port()}/small.bin"),))
    result = CliRunner().invoke(app, ["datasets", "download", NAME, "--to", str(tmp_path), "--quiet"])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {NAME}: cannot download") and "offline" in lines[0]
    assert not (tmp_path / NAME).exists() and not (tmp_path / (NAME + ".part")).exists()


def test_http_error_names_file_and_code(server, monkeypatch, tmp_path):
    monkeypatch.setattr(catalog, "CATALOGUE", (_entry(f"http://127.0.0.1:{server.server_port}/gone.bin"),))
    with pytest.raises(InputError, match=f"{NAME}: HTTP 404"):
        download([NAME], tmp_path, quiet=True)


def test_unknown_name_lists_folders():
    with pytest.raises(InputError, match="nope: no such data file or folder.*radish"):
        select(["nope"])


def test_list_shows_names_and_status(served, tmp_path, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")
    runner = CliRunner()
    before = runner.invoke(app, ["datasets", "list", "--root", str(tmp_path), "--format", "table"])
    assert before.exit_code == 0 and NAME in before.stdout and "missing" in before.stdout
    assert "CC0-1.0" in before.stdout and hashlib.sha256(PAYLOAD).hexdigest()[:16] in before.stdout
    fetched = runner.invoke(app, ["datasets", "download", "all", "--to", str(tmp_path)])  # with progress bar
    assert fetched.exit_code == 0 and f"verified: 1 file(s) in {tmp_path}" in fetched.stdout
    after = runner.invoke(app, ["datasets", "list", "--root", str(tmp_path)])
    assert "verified" in after.stdout and "missing" not in after.stdout


def test_list_plain_and_json_for_scripts(served, tmp_path):
    runner = CliRunner()
    plain = runner.invoke(app, ["datasets", "list", "--root", str(tmp_path)])  # stdout not a terminal: plain
    assert plain.exit_code == 0, plain.output
    header, line = plain.stdout.splitlines()
    assert header.split("\t") == ["file", "size", "sha256", "status", "licence", "source", "url", "purpose"]
    host = f"127.0.0.1:{served.server_port}"
    assert line.split("\t") == [NAME, str(len(PAYLOAD)), hashlib.sha256(PAYLOAD).hexdigest(), "missing", "CC0-1.0",
                                host, f"http://{host}/small.bin", "download tests"]
    listed = runner.invoke(app, ["datasets", "list", "--root", str(tmp_path), "--format", "json"])
    assert listed.exit_code == 0, listed.output
    assert json.loads(listed.stdout) == [dict(zip(header.split("\t"), [*line.split("\t")[:1], len(PAYLOAD),
                                                                        *line.split("\t")[2:]]))]
    bad = runner.invoke(app, ["datasets", "list", "--format", "yaml"])
    assert bad.exit_code == 2 and "--format" in bad.output


def test_catalogue_matches_the_data(data_file):
    """Every catalogued file: the size and sha256 of the copy under SLAM2D_DATA; URLs pinned to a commit."""
    names = [f.name for f in catalog.CATALOGUE]
    assert len(names) == len(set(names)) == 50
    assert {f.group for f in catalog.CATALOGUE} == {"radish", "posegraphs", "rooms", "movingai"}
    for entry in catalog.CATALOGUE:
        path = data_file(entry.name)
        assert (path.stat().st_size, sha256_of(path)) == (entry.size, entry.sha256), entry.name
        assert re.fullmatch(r"https://raw\.githubusercontent\.com/[\w.-]+/[\w.-]+/[0-9a-f]{40}/\S+", entry.url)
        assert entry.licence and entry.purpose and entry.origin
