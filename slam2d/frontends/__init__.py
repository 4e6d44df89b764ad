"""Scan-matching frontends; importing this package registers the built-in ones."""

from slam2d.frontends.base import (  # noqa: F401
    FRONTENDS,
    Frontend,
    FrontendResult,
    available_frontends,
    create_frontend,
    register_frontend,
)
