"""``rhbl foxglove`` under the console's rules: an upgrade from a foreign web page's Origin, or
naming a foreign Host without a token, is refused (it got 101 and the live server info); a
token is required when one is set; an address other than loopback needs TLS. Each refusal has
a positive control: the same request, allowed, gets 101."""

from __future__ import annotations

import base64
import json
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest
from waiting import eventually, listening

from lab.children import Child

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def bridge(free_port, tmp_path):
    started = []

    def start(*extra: str) -> tuple[Child, int]:
        port = free_port()
        child = Child("foxglove", [sys.executable, "-m", "lab.cli", "foxglove", "--mode", "peer",
                                   "--listen", f"tcp/127.0.0.1:{free_port()}", "--port",
                                   str(port), *extra], cwd=ROOT)
        child.start()
        started.append(child)
        eventually(lambda: listening(port), 60, f"the bridge listening on port {port}",
                   alive=[child])
        return child, port

    yield start
    for child in started:
        child.stop()


def upgrade(port: int, path: str = "/", host: str | None = None, origin: str | None = None,
            extra: str = "", source: str = "127.0.0.1") -> str:
    """The status line of a WebSocket upgrade sent to the bridge."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [f"GET {path} HTTP/1.1", *([f"Host: {host}"] if host is not None else []),
             "Upgrade: websocket", "Connection: Upgrade", f"Sec-WebSocket-Key: {key}",
             "Sec-WebSocket-Version: 13", "Sec-WebSocket-Protocol: foxglove.sdk.v1",
             *([f"Origin: {origin}"] if origin is not None else [])]
    with socket.create_connection(("127.0.0.1", port), timeout=30, source_address=(source, 0)) as s:
        s.sendall(("\r\n".join(lines) + "\r\n" + extra + "\r\n").encode())
        got = b""
        while b"\r\n" not in got:
            part = s.recv(4096)
            if not part:
                break
            got += part
    return got.split(b"\r\n", 1)[0].decode()


def test_foreign_origins_and_hosts_are_refused_loopback_apps_served(bridge):
    from websockets.sync.client import connect

    child, port = bridge("--allow-origin", "https://app.foxglove.dev")
    here = f"127.0.0.1:{port}"
    assert " 101 " in upgrade(port, host=here)  # a desktop app or a program: no Origin
    assert " 101 " in upgrade(port, host=f"localhost:{port}", origin="https://app.foxglove.dev")
    assert " 403 " in upgrade(port, host=here, origin="http://evil.example")
    assert " 403 " in upgrade(port, host=f"attacker.example:{port}")  # DNS rebinding
    assert " 403 " in upgrade(port, host=None)
    assert " 400 " in upgrade(port, host=here, extra="Origin: a\r\nOrigin: b\r\n")
    assert " 431 " in upgrade(port, host=here, extra="X-Long: " + "x" * 10_000 + "\r\n")
    with socket.create_connection(("127.0.0.1", port), timeout=30) as s:  # not a WebSocket
        s.sendall(f"GET / HTTP/1.1\r\nHost: {here}\r\n\r\n".encode())
        assert b" 400 " in s.recv(4096)
    with connect(f"ws://{here}", subprotocols=["foxglove.sdk.v1"], open_timeout=20) as ws:
        assert json.loads(ws.recv(timeout=20))["op"] == "serverInfo"  # relayed to the SDK
    assert child.wait_for_line("refused a request from", 10), child.output()


TOKEN = "k3y-0f-the-f0xglove-test"


def test_a_token_is_required_when_set(bridge):
    child, port = bridge("--token", TOKEN)
    assert child.wait_for_line(f"ws://127.0.0.1:{port}/?token={TOKEN}", 10), child.output()
    assert " 401 " in upgrade(port, host=f"127.0.0.1:{port}")
    assert " 401 " in upgrade(port, path="/?token=wrong", host=f"127.0.0.1:{port}")
    assert " 101 " in upgrade(port, path=f"/?token={TOKEN}", host=f"any.name:{port}")


def test_wrong_tokens_are_throttled_per_address(bridge):
    """A burst of wrong tokens from one address: the first few are checked (401), then that
    address waits (429 with Retry-After), even with the right token; another address is not
    held up."""
    _child, port = bridge("--token", TOKEN)
    said = [upgrade(port, path="/?token=wrong", host=f"127.0.0.1:{port}") for _ in range(30)]
    assert said[0].startswith("HTTP/1.1 401") and said[-1].startswith("HTTP/1.1 429"), said
    assert " 429 " in upgrade(port, path=f"/?token={TOKEN}", host=f"127.0.0.1:{port}")
    assert " 101 " in upgrade(port, path=f"/?token={TOKEN}", host=f"127.0.0.1:{port}",
                              source="127.0.0.2")


@pytest.mark.parametrize("token", ["a", "s3cret", "aaaaaaaaaaaaaaaaaaaaaaaa"])
def test_a_weak_token_is_refused_before_any_connection(token):
    r = subprocess.run([sys.executable, "-m", "lab.cli", "foxglove", f"--token={token}",
                        "--connect", "tcp/127.0.0.1:9"], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "weak" in lines[0], r.stderr


def test_another_address_without_tls_is_refused_before_any_connection():
    r = subprocess.run([sys.executable, "-m", "lab.cli", "foxglove", "--host", "0.0.0.0",
                        "--connect", "tcp/127.0.0.1:9"], cwd=ROOT, capture_output=True,
                       text=True, timeout=60)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and "--tls-cert" in lines[0], r.stderr
