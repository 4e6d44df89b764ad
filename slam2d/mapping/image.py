"""Grey images as 8-bit arrays: the one reader of map, floor-plan and world images."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from slam2d.errors import InputError
from slam2d.limits import check_memory

IMAGE_BYTES_PER_PIXEL = 24  # reading an image as a map: the pixels, the log-odds grid and temporaries
WIDE_GREY = ("I;16", "I;16B", "I;16L", "I")
"""PIL modes of 16- and 32-bit grey images, scaled (not clipped) to 8 bits."""


def read_grey(path) -> np.ndarray:
    """(H, W) uint8 grey values of the image at ``path`` (row 0 the top); an InputError if it is not an image."""
    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():  # PIL warns of a large image: check_size refuses it instead
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            im = Image.open(Path(path))
        with im:
            check_size(im, path)
            return grey8(im)
    except FileNotFoundError:
        raise InputError(path, "image not found") from None
    except InputError:
        raise
    except Image.DecompressionBombError as err:
        raise InputError(path, f"image too large ({str(err)[:160]})") from None
    except (UnidentifiedImageError, OSError, ValueError) as err:
        raise InputError(path, f"not a readable image ({str(err)[:120]})") from None


def check_size(im, path) -> None:
    """InputError if the PIL image ``im`` has more than PIL's ``MAX_IMAGE_PIXELS`` pixels (a decompression
    bomb, or a map larger than any building) or would not fit in memory as a map."""
    from PIL import Image

    w, h = im.size
    if Image.MAX_IMAGE_PIXELS and w * h > Image.MAX_IMAGE_PIXELS:
        raise InputError(path, f"image too large: {w} x {h} pixels, more than {Image.MAX_IMAGE_PIXELS}")
    check_memory(w * h * IMAGE_BYTES_PER_PIXEL, str(path), f"a {w} x {h} pixel map")


def grey8(im) -> np.ndarray:
    """8-bit grey values of a PIL image; 16- and 32-bit grey images are scaled to their full range."""
    if im.mode not in WIDE_GREY:
        return np.asarray(im.convert("L"), dtype=np.uint8)
    v = np.asarray(im).astype(np.int64)
    top = 65535 if im.mode != "I" or v.max(initial=0) <= 65535 else int(v.max())
    return np.round(np.clip(v, 0, top) * (255.0 / top)).astype(np.uint8)
