"""`station serve` over HTTPS: a real server on 127.0.0.1 with a self-signed certificate (made by openssl), the
operator's session cookie marked Secure there and only there, and the certificate options checked before the
server starts."""

from __future__ import annotations

import http.client
import json
import os
import shutil
import socket
import ssl
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from station.cli import app
from station.store import open_database
from station.web.app import create_app

STATION = str(Path(sys.executable).with_name("station"))


def _cookie_after_sign_in(https_only: bool, tmp_path: Path) -> str:
    db = open_database(f"sqlite:///{tmp_path / f'c{int(https_only)}.sqlite'}")
    try:
        web = create_app(database=db, session_key="k" * 32, https_only=https_only)
        with TestClient(web, base_url="https://testserver") as client:
            r = client.post("/api/operator/session", json={"name": "alice", "role": "operator"})
            assert r.status_code == 200, r.text
            return r.headers["set-cookie"].lower()
    finally:
        db.close()


def test_the_session_cookie_is_secure_only_when_served_with_tls(tmp_path: Path) -> None:
    secure = _cookie_after_sign_in(True, tmp_path)
    plain = _cookie_after_sign_in(False, tmp_path)
    assert "station_operator=" in secure and "; secure" in secure and "samesite=strict" in secure
    assert "station_operator=" in plain and "secure" not in plain


def test_a_certificate_without_its_key_or_a_file_that_is_none_is_refused_in_one_line(tmp_path: Path) -> None:
    db = f"sqlite:///{tmp_path / 's.sqlite'}"
    out = CliRunner().invoke(app, ["serve", "--db", db, "--tls-cert", str(tmp_path / "c.pem")])
    assert out.exit_code == 2 and "--tls-cert and --tls-key go together" in out.output
    junk = tmp_path / "junk.pem"
    junk.write_text("not a certificate\n")
    out = CliRunner().invoke(app, ["serve", "--db", db, "--tls-cert", str(junk), "--tls-key", str(junk)])
    assert out.exit_code == 2 and "cannot be used" in out.output and "Traceback" not in out.output, out.output
    out = CliRunner().invoke(app, ["serve", "--db", db, "--tls-cert", str(tmp_path / "no.pem"),
                                   "--tls-key", str(junk)])
    assert out.exit_code == 2 and "is not a file" in out.output, out.output


@pytest.fixture
def certificate(tmp_path: Path) -> tuple[Path, Path]:
    if shutil.which("openssl") is None:
        pytest.skip("openssl is not installed")
    cert, key = tmp_path / "cert.pem", tmp_path / "key.pem"
    subprocess.run(["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1", "-subj",
                    "/CN=127.0.0.1", "-addext", "subjectAltName=IP:127.0.0.1", "-keyout", str(key), "-out",
                    str(cert)], check=True, capture_output=True)
    return cert, key


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def https_server(tmp_path: Path, certificate: tuple[Path, Path]) -> Iterator[tuple[int, Path]]:
    cert, key = certificate
    port = _free_port()
    proc = subprocess.Popen([STATION, "serve", "--port", str(port), "--db", f"sqlite:///{tmp_path / 's.sqlite'}",
                             "--tls-cert", str(cert), "--tls-key", str(key)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=os.environ.copy())
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert proc.poll() is None, proc.stdout.read() if proc.stdout else ""
                time.sleep(0.2)
        yield port, cert
    finally:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@pytest.mark.integration
def test_serve_answers_over_https_with_a_secure_cookie_and_not_over_plain_http(
    https_server: tuple[int, Path]
) -> None:
    port, cert = https_server
    context = ssl.create_default_context(cafile=str(cert))  # the certificate is checked, not ignored
    conn = http.client.HTTPSConnection("127.0.0.1", port, context=context, timeout=20)
    conn.request("GET", "/api/operator/session")
    r = conn.getresponse()
    assert r.status == 200 and json.loads(r.read()) == {"signed_in": False, "name": "", "role": ""}
    conn.request("POST", "/api/operator/session", body=json.dumps({"name": "alice", "role": "operator"}),
                 headers={"Content-Type": "application/json"})
    r = conn.getresponse()
    body = json.loads(r.read())
    assert r.status == 200 and body["signed_in"] is True
    cookie = (r.getheader("set-cookie") or "").lower()
    assert "station_operator=" in cookie and "; secure" in cookie
    conn.close()
    plain = http.client.HTTPConnection("127.0.0.1", port, timeout=20)
    with pytest.raises((http.client.HTTPException, OSError)):
        plain.request("GET", "/api/operator/session")
        plain.getresponse().read()
    plain.close()
