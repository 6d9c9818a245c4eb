"""``rhbl console``'s pure parts: the --http address, when a token is required, how strong it
must be, how wrong ones are throttled, key helpers."""

from __future__ import annotations

import pytest

pytest.importorskip("aiohttp")

from client.access import access_token  # noqa: E402
from client.roles.console.app import _action_of, parse_http  # noqa: E402
from lab.cli import build_parser  # noqa: E402


def test_parse_http():
    assert parse_http("127.0.0.1:8080") == ("127.0.0.1", 8080)
    assert parse_http("[::1]:0") == ("::1", 0)
    for bad in ("8080", "host:", ":80", "h:70000", "h:x"):
        with pytest.raises(ValueError, match="HOST:PORT"):
            parse_http(bad)


def test_host_name():
    from client.access import host_name

    assert host_name("[::1]:8080") == "::1" and host_name("[::1]") == "::1"
    assert host_name("localhost:80") == "localhost" and host_name("127.0.0.1") == "127.0.0.1"


def test_a_token_is_required_beyond_loopback():
    assert access_token("127.0.0.1", None) is None
    assert access_token("localhost", None) is None
    assert access_token("::1", None) is None
    a, b = access_token("0.0.0.0", None), access_token("192.0.2.7", None)
    assert a and b and a != b and len(a) >= 20  # random, unguessable
    assert access_token("127.0.0.1", "given") == "given"
    assert access_token("0.0.0.0", "") != ""  # an empty --token (compose's default) is none


def test_weak_tokens_are_refused_with_the_rule_not_the_token():
    from client.access import check_strength

    for weak in ("a", "s3cret", "short-token-15ch", "aaaaaaaaaaaaaaaaaaaaaaaa", "abababababababab"):
        if len(weak) >= 16 and len(set(weak)) >= 8:
            continue
        with pytest.raises(ValueError, match="at least 16 characters, 8 of them different") as e:
            check_strength(weak)
        assert weak not in str(e.value) or len(weak) == 1
    for _ in range(200):  # the random tokens pass, always
        check_strength(access_token("0.0.0.0", None))
    check_strength("0123456789abcdef")


def test_wrong_tokens_are_throttled_per_address():
    from client.access import BURST, Throttle

    now = [0.0]
    t = Throttle(clock=lambda: now[0])
    for _ in range(BURST):
        assert t.wait("10.0.0.1") == 0
        t.failed("10.0.0.1")
    assert t.wait("10.0.0.1") == pytest.approx(1.0)  # then one a second
    assert t.wait("10.0.0.2") == 0  # another address is not concerned
    now[0] += 0.5
    assert t.wait("10.0.0.1") == pytest.approx(0.5)
    now[0] += 0.5
    assert t.wait("10.0.0.1") == 0
    t.failed("10.0.0.1")
    assert t.wait("10.0.0.1") > 0
    now[0] += 3600
    assert t.wait("10.0.0.1") == 0 and t.throttled == 3


def test_action_names():
    from client.behaviour.actions import DEFAULT_ACTIONS

    for name, (vx, va) in DEFAULT_ACTIONS.items():
        assert _action_of(vx, va) == name
    assert _action_of(0.0, 0.0) == "stop"


def test_cli_flags():
    args = build_parser("console").parse_args([])
    assert args.http == "127.0.0.1:8080" and args.token is None and not args.view_only
    args = build_parser("console").parse_args(["--http", "0.0.0.0:9", "--view-only"])
    assert args.http == "0.0.0.0:9" and args.view_only


@pytest.mark.parametrize("argv, said", [
    (["--http", "nonsense"], "--http must be HOST:PORT"),
    (["--tls-cert", "c.pem"], "--tls-cert and --tls-key go together"),
    (["--header-timeout", "0"], "--header-timeout must be a finite number > 0 and <= 3600"),
    (["--header-timeout", "nan"], "--header-timeout must be a finite number > 0 and <= 3600"),
    (["--header-timeout", "-5"], "--header-timeout must be a finite number > 0 and <= 3600"),
])
def test_bad_flags_exit_2_before_opening_a_session(argv, said, tmp_path):
    import os
    import subprocess
    import sys

    (tmp_path / "c.pem").write_text("")
    r = subprocess.run([sys.executable, "-m", "lab.cli", "console", *argv,
                        "--connect", "tcp/127.0.0.1:9"], capture_output=True, text=True,
                       cwd=tmp_path,
                       timeout=60, env={**os.environ, "RHBL_LOG_LEVEL": "INFO"})
    assert r.returncode == 2 and said in r.stderr, r.stderr


def test_home_before_the_world_is_known_says_so_and_how_long_to_wait():
    """Home (or a start pose) before the simulator answered: the world is not known yet,
    try again once the map is drawn; a world without start poses says that instead."""
    from client.roles.console.tutor import Robot, _no_starts

    r = Robot("r0")
    assert "world is not known yet" in _no_starts(r) and "map is drawn" in _no_starts(r)
    r.world = "{}"
    assert _no_starts(r) == "the world gives no start poses"
