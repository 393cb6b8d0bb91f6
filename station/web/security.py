"""Security headers on every answer of the web application, as one ASGI middleware.

Every answer: ``X-Content-Type-Options: nosniff`` (a browser takes the declared type, never guesses one),
``X-Frame-Options: DENY`` (no page of the station inside another site's frame) and ``Referrer-Policy:
same-origin``. HTML pages also get a Content-Security-Policy: everything from the station itself, nothing
from elsewhere, no framing, forms only to the station. The pages keep their scripts and styles inline
(server-rendered templates without a build step), so the policy allows inline script and style but no
other origin; FastAPI's interactive API pages (``/docs``, ``/redoc``) load their viewer from a CDN and are
left without the policy (they show only the OpenAPI document).
"""

from __future__ import annotations

from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

#: The Content-Security-Policy of the station's HTML pages.
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; script-src 'self' 'unsafe-inline'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'self'; form-action 'self'; "
    "frame-ancestors 'none'"
)

COMMON_HEADERS = (
    (b"x-content-type-options", b"nosniff"),
    (b"x-frame-options", b"DENY"),
    (b"referrer-policy", b"same-origin"),
)

#: Paths whose pages load FastAPI's documentation viewer from its CDN (no CSP there).
DOC_VIEWERS = ("/docs", "/redoc")


class SecurityHeaders:
    """ASGI middleware adding the headers of the module docstring to every HTTP answer."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        viewer = str(scope.get("path", "")).startswith(DOC_VIEWERS)

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers: list[Any] = list(message.get("headers", []))
                present = {k.lower() for k, _ in headers}
                headers += [(k, v) for k, v in COMMON_HEADERS if k not in present]
                content_type = next((v for k, v in headers if k.lower() == b"content-type"), b"")
                if content_type.startswith(b"text/html") and not viewer and b"content-security-policy" not in present:
                    headers.append((b"content-security-policy", CONTENT_SECURITY_POLICY.encode("ascii")))
                message["headers"] = headers
            await send(message)

        await self.app(scope, receive, send_with_headers)


__all__ = ["COMMON_HEADERS", "CONTENT_SECURITY_POLICY", "SecurityHeaders"]
