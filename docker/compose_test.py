"""``make compose-test``: docker/compose.yaml's scenario in real containers, checked from outside.

    python docker/compose_test.py                 # podman (with podman-compose), else Docker
    python docker/compose_test.py --engine docker --keep-images

Each step is timed and printed:

1. the engine: podman with podman-compose (PyPI), else Docker with ``docker compose``;
2. the Python base image: the Dockerfile's ``PYTHON_IMAGE`` (python:3.11-slim-bookworm) if it
   is here or can be pulled, else a stand-in made from Debian's own packages with mmdebstrap
   (``rhbl-python-standin:3.11-bookworm``, kept for the next run: only its first run makes it);
3. the rhbl image, from docker/Dockerfile as it stands with only ``PYTHON_IMAGE`` set;
4. the router image: ``eclipse/zenoh`` if it is here or can be pulled, else the stand-in of
   docker/router-standin.Dockerfile (``rhbl-router-standin:<version>``, never eclipse/zenoh);
5. ``compose up`` under a project name of its own (``rhbl-compose-test-<pid>``, never
   ``rhbl``), the router and the console on free ports of 127.0.0.1, the teacher shortened;
6. checks from the host: every service started (and when), an anonymous zenoh client is refused
   by the secured router while a credentialed one is accepted, the learner's tree grew, the
   controller drove the robot with it once the teacher stopped, the teacher's labels were all
   acknowledged, the console answered, every health check passes when run, the image runs as a
   non-root user with a read-only root filesystem where the role allows, and the laser kernels
   compiled into the image are loaded, not compiled again;
7. ``compose down -v``, then a check that no container, network or volume of the project is
   left; the images this run built are removed (the base image stays cached).

Exit status: 0 every check passed, 1 a check or a step failed, 2 bad arguments, 3 no container
engine here (``--probe`` only says which engine would be used). Whatever it started is removed
on every path (Ctrl-C and SIGTERM included).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import fcntl
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path

import compose_local
import router_standin

from lab.children import free_port

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
COMPOSE_FILE = HERE / "compose.yaml"
DOCKERFILE = HERE / "Dockerfile"
ROUTER_DOCKERFILE = HERE / "router-standin.Dockerfile"
CONTAINERS_CONF = HERE / "containers.conf"
LOCK_FILE = HERE / "requirements.lock"

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NO_ENGINE = 0, 1, 2, 3
ROBOT = "r0"
ROLES = ("server", "learner", "teacher", "controller", "console")
# roles whose root filesystem compose makes read-only (the server, the learner and the
# controller need a writable one: numba loads the image's compiled kernels, the laser's, the
# tree's and the scan reader's, only from a folder it can write to)
READ_ONLY = ("secrets", "teacher", "console")
NUMBA_CACHE = "/var/cache/rhbl-numba"  # the Dockerfile's NUMBA_CACHE_DIR
HOST_CA_BUNDLE = Path("/etc/ssl/certs/ca-certificates.crt")
PROJECT_LABEL = "com.docker.compose.project"
SERVICE_LABEL = "com.docker.compose.service"

# ---- the Python base image made from Debian packages ----------------------------------------
BASE_STANDIN = "localhost/rhbl-python-standin:3.11-bookworm"
BASE_VENV = "/opt/python"  # python and pip come first on PATH, as in python:*-slim
BASE_PACKAGES = ("ca-certificates", "python3", "python3-venv")
BASE_SOURCES = (
    "deb {mirror} bookworm main",
    "deb {mirror} bookworm-updates main",
    "deb {security} bookworm-security main",
)
BASE_OPTIONS = (
    "--variant=minbase",
    # merged /usr set up by mmdebstrap itself, not by the usrmerge package (and its perl)
    "--hook-dir=/usr/share/mmdebstrap/hooks/merged-usr",
    # like the slim images: no manuals, translations or documentation (copyright files kept)
    "--dpkgopt=path-exclude=/usr/share/man/*",
    "--dpkgopt=path-exclude=/usr/share/locale/*",
    "--dpkgopt=path-exclude=/usr/share/doc/*",
    "--dpkgopt=path-include=/usr/share/doc/*/copyright",
    f'--customize-hook=chroot "$1" python3 -m venv {BASE_VENV}',
)
BASE_CHANGES = (
    f"ENV PATH={BASE_VENV}/bin:/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
    "ENV LANG=C.UTF-8",
    'CMD ["python3"]',
)


class StepFailed(RuntimeError):
    """A step could not be done (the message says which and why)."""


def _say(text: str) -> None:
    print(f"compose-test: {text}", flush=True)


def _tail(text: str, n: int = 25) -> str:
    return "\n".join("    " + ln for ln in text.strip().splitlines()[-n:])


# ---- the engine ---------------------------------------------------------------------------------
@dataclass
class Engine:
    """A container engine's command line: podman (+ podman-compose) or docker (+ compose)."""

    name: str
    compose: list[str]
    env: dict[str, str] = field(default_factory=lambda: dict(os.environ))

    def run(self, *args: str, timeout: float = 120, check: bool = True, log: Path | None = None,
            env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
        return _run([self.name, *args], self.env if env is None else env, timeout, check, log)

    def compose_run(self, project: str, *args: str, env: dict[str, str], timeout: float = 300,
                    log: Path | None = None) -> subprocess.CompletedProcess:
        argv = [*self.compose, "-p", project, "-f", str(COMPOSE_FILE), *args]
        return _run(argv, env, timeout, True, log)

    def image_exists(self, image: str) -> bool:
        return self.run("image", "inspect", image, check=False, timeout=60).returncode == 0

    def pull(self, image: str, timeout: float) -> tuple[bool, str]:
        try:
            run = self.run("pull", image, check=False, timeout=timeout)
        except subprocess.TimeoutExpired:
            return False, f"no answer in {timeout:.0f} s"
        lines = (run.stdout + run.stderr).strip().splitlines()
        return run.returncode == 0, (lines[-1] if lines else "")

    def build(self, dockerfile: Path, tag: str, build_args: dict[str, str], log: Path,
              timeout: float = 1800) -> None:
        argv = ["build", "-f", str(dockerfile), "-t", tag]
        for key, value in build_args.items():
            argv += ["--build-arg", f"{key}={value}"]
        if self.name == "podman":
            # the Docker image format keeps the HEALTHCHECK; no intermediate images are kept
            argv += ["--format", "docker", "--layers=false"]
            if HOST_CA_BUNDLE.is_file():  # pip in the build trusts what this host trusts
                argv += ["-v", f"{HOST_CA_BUNDLE}:{HOST_CA_BUNDLE}:ro"]
        self.run(*argv, str(ROOT), timeout=timeout, log=log)

    def inspect(self, *ids: str) -> list[dict]:
        if not ids:
            return []
        return json.loads(self.run("inspect", *ids, timeout=60).stdout)

    def healthcheck(self, container: dict) -> tuple[bool, str]:
        """Run the container's health check once, as the engine would: (passed, output)."""
        if self.name == "podman":  # healthchecks are not scheduled without systemd
            run = self.run("healthcheck", "run", container["Id"], check=False, timeout=60)
            state = self.inspect(container["Id"])[0]["State"]
            logged = (state.get("Health") or state.get("Healthcheck") or {}).get("Log") or []
            if logged and logged[-1].get("Output"):  # what the check itself printed
                run.stdout += "\n" + logged[-1]["Output"]
        else:  # Docker schedules them itself; run the same command now
            test = (container["Config"].get("Healthcheck") or {}).get("Test") or []
            if not test or test[0] not in ("CMD", "CMD-SHELL"):
                return False, f"no health check ({test})"
            cmd = test[1:] if test[0] == "CMD" else ["sh", "-c", test[1]]
            run = self.run("exec", container["Id"], *cmd, check=False, timeout=60)
        out = (run.stdout + run.stderr).strip()
        return run.returncode == 0, out.splitlines()[-1] if out else f"exit {run.returncode}"


def _run(argv: list[str], env: dict[str, str], timeout: float, check: bool,
         log: Path | None) -> subprocess.CompletedProcess:
    run = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=timeout,
                         stdin=subprocess.DEVNULL)
    if log is not None:
        with open(log, "a") as f:
            f.write(f"$ {' '.join(argv)}\n{run.stdout}{run.stderr}\n")
    if check and run.returncode != 0:
        raise StepFailed(f"`{' '.join(argv[:4])} ...` exited {run.returncode}:\n"
                         + _tail(run.stdout + run.stderr))
    return run


def _tool(name: str) -> str | None:
    """On PATH, or beside this interpreter (the project's virtual environment)."""
    return shutil.which(name) or shutil.which(name, path=str(Path(sys.executable).parent))


def find_engine(prefer: str | None = None) -> Engine | str:
    """The engine to use, or why there is none."""
    why = []
    for name in ((prefer,) if prefer else ("podman", "docker")):
        if name == "podman":
            if not shutil.which("podman"):
                why.append("no podman")
                continue
            compose = _tool("podman-compose")
            if compose is None:
                why.append("podman but no podman-compose (pip install podman-compose; "
                           "`make install` puts it in .venv)")
                continue
            env = dict(os.environ)
            if "CONTAINERS_CONF" not in env and shutil.which("runc"):
                env["CONTAINERS_CONF"] = str(CONTAINERS_CONF)
            engine = Engine("podman", [compose], env)
        else:
            if not shutil.which("docker"):
                why.append("no docker")
                continue
            engine = Engine("docker", ["docker", "compose"])
            if engine.run("compose", "version", check=False, timeout=30).returncode != 0:
                why.append("docker without its compose plugin")
                continue
        info = engine.run("info", check=False, timeout=60)
        if info.returncode != 0:
            lines = (info.stderr or info.stdout).strip().splitlines()
            why.append(f"{name} does not answer ({lines[-1] if lines else info.returncode})")
            continue
        return engine
    return "no container engine: " + "; ".join(why)


# ---- the report ---------------------------------------------------------------------------------
class Report:
    """Timed steps and named checks, printed as they happen."""

    def __init__(self) -> None:
        self.steps: list[tuple[str, float]] = []
        self.checks: list[tuple[str, bool, str]] = []
        self.t0 = time.monotonic()

    @contextlib.contextmanager
    def step(self, name: str):
        t = time.monotonic()
        _say(f"{name} ...")
        try:
            yield
        finally:
            seconds = time.monotonic() - t
            self.steps.append((name, seconds))
            _say(f"{name}: {seconds:.1f} s")

    def check(self, name: str, ok: bool, detail: str) -> bool:
        self.checks.append((name, ok, detail))
        _say(f"{'ok  ' if ok else 'FAIL'} {name}: {detail}")
        return ok

    def summary(self) -> str:
        rows = [f"| {name} | {seconds:.1f} |" for name, seconds in self.steps]
        failed = [name for name, ok, _ in self.checks if not ok]
        return "\n".join([
            "| step | seconds |", "|---|---|", *rows,
            f"| total | {time.monotonic() - self.t0:.1f} |",
            f"checks: {len(self.checks) - len(failed)} passed, {len(failed)} failed"
            + (f" ({', '.join(failed)})" if failed else ""),
        ])

    @property
    def passed(self) -> bool:
        return bool(self.checks) and all(ok for _, ok, _ in self.checks)


# ---- images -------------------------------------------------------------------------------------
def _qualified(image: str) -> str:
    """``python:3.11`` -> ``docker.io/library/python:3.11`` (podman does not guess registries)."""
    first = image.split("/")[0]
    if "/" not in image:
        return f"docker.io/library/{image}"
    if "." in first or ":" in first or first == "localhost":
        return image
    return f"docker.io/{image}"


def dockerfile_default(name: str, path: Path = DOCKERFILE) -> str:
    found = re.search(rf"^ARG {name}=(\S+)", path.read_text(), re.M)
    if not found:
        raise StepFailed(f"{path.name} has no default for ARG {name}")
    return found.group(1)


def base_recipe(mirror: str, security: str) -> tuple[list[str], str]:
    """mmdebstrap's arguments (after the options) and a digest of the whole recipe."""
    sources = [s.format(mirror=mirror, security=security) for s in BASE_SOURCES]
    argv = [*BASE_OPTIONS, f"--include={','.join(BASE_PACKAGES)}", "bookworm"]
    digest = hashlib.sha256(json.dumps([argv, sources, BASE_CHANGES]).encode()).hexdigest()[:16]
    return [*argv, "{tarball}", *sources], digest


def make_base(engine: Engine, workdir: Path, mirror: str, security: str) -> str:
    """The Debian-made stand-in of python:3.11-slim-bookworm: cached, else made now."""
    argv, digest = base_recipe(mirror, security)
    label = f"rhbl.base-recipe={digest}"
    with open(Path(tempfile.gettempdir()) / "rhbl-python-standin.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # two runs at once make it once
        if engine.image_exists(BASE_STANDIN):
            have = engine.run("image", "inspect", "--format",
                              '{{index .Config.Labels "rhbl.base-recipe"}}', BASE_STANDIN).stdout
            if have.strip() == digest:
                _say(f"base image: {BASE_STANDIN} (cached, recipe {digest})")
                return BASE_STANDIN
            _say(f"base image: {BASE_STANDIN} was made by another recipe: making it again")
        if not shutil.which("mmdebstrap"):
            raise StepFailed("mmdebstrap is needed to make the base image from Debian packages "
                             "(apt-get install mmdebstrap; scripts/ci-containers.sh does it)")
        tarball = workdir / "rootfs.tar"
        _say(f"base image: mmdebstrap {' '.join(BASE_PACKAGES)} (Debian bookworm) ...")
        _run(["mmdebstrap", *[a.replace("{tarball}", str(tarball)) for a in argv]],
             dict(os.environ), 1800, True, workdir / "mmdebstrap.log")
        changes = [a for c in (*BASE_CHANGES, f"LABEL {label}") for a in ("--change", c)]
        engine.run("import", *changes, str(tarball), BASE_STANDIN, timeout=600)
        tarball.unlink()
        _say(f"base image: made {BASE_STANDIN} from Debian packages (recipe {digest})")
        return BASE_STANDIN


def size_mb(engine: Engine, image: str) -> float:
    return int(engine.run("image", "inspect", "--format", "{{.Size}}", image).stdout) / 1e6


# ---- watching the scenario through zenoh --------------------------------------------------------
class Watch:
    """A zenoh session on the host with the teacher's credentials (they may read everything the
    checks need): liveliness tokens, tree notices, the controller's decisions, who drives and
    the robot's state. Callbacks only decode and store."""

    def __init__(self, config) -> None:
        import zenoh

        from protocol import keys
        from protocol.messages import Decision, DriverState, State, TreeNotice

        self._decode = {"notice": TreeNotice.decode, "decision": Decision.decode,
                        "driver": DriverState.decode, "state": State.decode}
        self.lock = threading.Condition()
        self.tokens: dict[str, float] = {}  # key -> when it appeared
        self.notices: list = []
        self.decisions: list = []
        self.drivers: list[tuple[float, str]] = []
        self.states: list[tuple[float, object]] = []
        self.session = zenoh.open(config)
        self._decls = [
            self.session.liveliness().declare_subscriber("rhbl/alive/**", self._on_token,
                                                         history=True),
            self.session.declare_subscriber(keys.learner_notice_key(ROBOT), self._on("notice")),
            self.session.declare_subscriber(keys.controller_decision_key(ROBOT),
                                            self._on("decision")),
            self.session.declare_subscriber(keys.driver_key(ROBOT), self._on("driver")),
            self.session.declare_subscriber(keys.state_key(ROBOT), self._on("state")),
        ]

    def _on_token(self, sample) -> None:
        import zenoh

        if sample.kind == zenoh.SampleKind.PUT:
            with self.lock:
                self.tokens.setdefault(str(sample.key_expr), time.time())
                self.lock.notify_all()

    def _on(self, what: str):
        store = {"notice": self.notices, "decision": self.decisions}.get(what)

        def on_sample(sample) -> None:
            try:
                msg = self._decode[what](sample.payload.to_bytes())
            except Exception:  # noqa: BLE001 - a malformed message is not ours to judge here
                return
            with self.lock:
                if store is not None:
                    store.append(msg)
                elif what == "driver":
                    self.drivers.append((time.time(), msg.source))
                else:
                    self.states.append((time.time(), msg))
                self.lock.notify_all()

        return on_sample

    def wait(self, predicate, timeout: float) -> bool:
        with self.lock:
            return self.lock.wait_for(predicate, timeout)

    def role_seen(self, role: str) -> bool:
        return any(k.startswith(f"rhbl/alive/{role}/") for k in self.tokens)

    def close(self) -> None:
        for decl in self._decls:
            with contextlib.suppress(Exception):
                decl.undeclare()
        self.session.close()


def client_config(secrets: Path, port: int, role: str | None, timeout_ms: int = 0):
    """A zenoh client of the published router with one role's credentials copied out of the
    secrets volume (their /run/secrets/ paths moved to ``secrets``), or none (``role`` None)."""
    import zenoh

    if role is None:
        config = zenoh.Config()
        config.insert_json5("transport/link/tls/root_ca_certificate",
                            json.dumps(str(secrets / "ca.pem")))
    else:
        config = router_standin.load_config(secrets / f"{role}.json5", secrets)
    config = compose_local.client_config(config, f"tls/127.0.0.1:{port}")
    config.insert_json5("connect/timeout_ms", str(timeout_ms))  # keep trying that long
    return config


# ---- the scenario -------------------------------------------------------------------------------
_STAMP = re.compile(r"^(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d)(?:\.(\d+))?(Z|[+-]\d\d:\d\d)?\s?(.*)$")


def _when(stamp: str) -> float:
    """An engine's RFC 3339 time (nanoseconds, ``Z`` or an offset) as a Unix time."""
    found = _STAMP.match(stamp.strip())
    if not found:
        raise ValueError(f"not a time stamp: {stamp!r}")
    base, frac, zone = found.group(1), found.group(2) or "0", found.group(3) or "+00:00"
    zone = "+00:00" if zone == "Z" else zone
    return dt.datetime.fromisoformat(f"{base}{zone}").timestamp() + float(f"0.{frac}")


def _timed_lines(text: str) -> list[tuple[float, str]]:
    out = []
    for line in text.splitlines():
        found = _STAMP.match(line)
        if found:
            out.append((_when(line.split(" ", 1)[0]), found.group(4)))
    return out


class Scenario:
    """One run: images, compose up, checks, compose down, clean-up."""

    def __init__(self, engine: Engine, args: argparse.Namespace, workdir: Path) -> None:
        self.engine = engine
        self.args = args
        self.workdir = workdir
        self.logs = workdir / "logs"
        self.logs.mkdir(parents=True, exist_ok=True)
        self.report = Report()
        run = f"{os.getpid()}"
        self.project = f"rhbl-compose-test-{run}"
        self.image = f"localhost/rhbl-compose-test:{run}"
        self.router_image: str | None = None
        self.built: list[str] = []  # images this run made (removed at the end)
        self.port, self.console_port = free_port(), free_port()
        self.env: dict[str, str] = {}
        self.up = False
        self.volumes: set[str] = set()  # every volume our containers mounted
        self.watch: Watch | None = None

    # -- images --
    def images(self) -> None:
        python_image = self.args.python_image
        with self.report.step("base image"):
            if python_image is None:
                python_image = self._upstream_or_none(dockerfile_default("PYTHON_IMAGE"))
            if python_image is None:
                python_image = make_base(self.engine, self.workdir, self.args.debian_mirror,
                                         self.args.debian_security)
        self.report.check("base image", True, f"{python_image}, "
                          f"{size_mb(self.engine, python_image):.0f} MB")
        with self.report.step("rhbl image"):
            if self.args.image:
                self.image = self.args.image
                _say(f"rhbl image: {self.image} (given: not built, not removed)")
            else:
                self.built.append(self.image)
                self.engine.build(DOCKERFILE, self.image, {"PYTHON_IMAGE": python_image},
                                  self.logs / "build-rhbl.log")
        with self.report.step("router image"):
            router = compose_local.load_compose(COMPOSE_FILE, env={})["services"]["router"]
            upstream = router["image"]
            self.router_image = self.args.router_image or self._upstream_or_none(upstream)
            if self.router_image is None:
                version = upstream.rsplit(":", 1)[1]
                self.router_image = f"localhost/rhbl-router-standin:{version}-{os.getpid()}"
                self.built.append(self.router_image)
                self.engine.build(ROUTER_DOCKERFILE, self.router_image,
                                  {"PYTHON_IMAGE": python_image},
                                  self.logs / "build-router.log")
                _say(f"router image: {upstream} cannot be had here: the stand-in "
                     f"{self.router_image} ({ROUTER_DOCKERFILE.name})")

    def _upstream_or_none(self, image: str) -> str | None:
        full = _qualified(image)
        for name in (image, full):
            if self.engine.image_exists(name):
                _say(f"{image}: here already")
                return name
        ok, why = self.engine.pull(full, self.args.pull_timeout)
        _say(f"pull {full}: {'done' if ok else 'failed: ' + why}")
        return full if ok else None

    # -- compose --
    def compose(self, *args: str, timeout: float = 300):
        return self.engine.compose_run(self.project, *args, env=self.env, timeout=timeout,
                                       log=self.logs / "compose.log")

    def start(self) -> None:
        self.env = dict(self.engine.env)
        self.env.update({
            "RHBL_IMAGE": self.image, "RHBL_ROUTER_IMAGE": self.router_image,
            "RHBL_ROUTER_ADDRESS": "127.0.0.1", "RHBL_PORT": str(self.port),
            "RHBL_CONSOLE_PORT": str(self.console_port),
            "RHBL_TEACH_SECONDS": str(self.args.teach_seconds),
            "RHBL_DEMONSTRATE_SECONDS": str(self.args.demonstrate_seconds),
        })
        _say(f"project {self.project}: router on 127.0.0.1:{self.port}, console on "
             f"127.0.0.1:{self.console_port}, teacher {self.args.teach_seconds} s")
        with self.report.step("compose up"):
            self.up = True
            self.compose("up", "-d", "--no-build", timeout=600)

    def containers(self) -> dict[str, dict]:
        """service -> its container's inspect record (every container of the project)."""
        ids = self.engine.run("ps", "-a", "-q", "--no-trunc", "--filter",
                              f"label={PROJECT_LABEL}={self.project}").stdout.split()
        out = {}
        for record in self.engine.inspect(*ids):
            out[record["Config"]["Labels"].get(SERVICE_LABEL, record["Name"])] = record
            for mount in record.get("Mounts", []):
                if mount.get("Type") == "volume" and mount.get("Name"):
                    self.volumes.add(mount["Name"])
        return out

    def container_logs(self, record: dict, timestamps: bool = True) -> str:
        stamps = ["--timestamps"] if timestamps else []
        run = self.engine.run("logs", *stamps, record["Id"], check=False, timeout=60)
        return run.stdout + run.stderr

    # -- checks --
    def run_checks(self) -> None:
        report = self.report
        secrets = self.workdir / "secrets"
        with report.step("services up"):
            found = self.containers()
            if "secrets" not in found:
                raise StepFailed(f"no secrets container in project {self.project}: {found}")
            secrets.mkdir(mode=0o700)
            self.engine.run("cp", f"{found['secrets']['Id']}:/run/secrets/.", str(secrets))
            self.watch = Watch(client_config(secrets, self.port, "teacher", timeout_ms=60_000))
            alive = self.watch.wait(lambda: all(self.watch.role_seen(r) for r in ROLES),
                                    self.args.start_timeout)
        self._check_started(alive)
        with report.step("health checks"):
            self._check_health(self.containers())
        self._check_refused(secrets)
        self._check_image()
        with report.step("teaching"):
            teacher = self.containers()["teacher"]
            self.engine.run("wait", teacher["Id"], timeout=self.args.teach_seconds + 180)
            gone = time.time()
            drove = self.watch.wait(lambda: len(self._driven_after(gone + 1.0)) >= 30, 30)
        self._check_taught(drove, gone)
        self._check_console()
        self._check_numba()
        self._save_tree()

    def _check_started(self, alive: bool) -> None:
        found = self.containers()
        seen = sorted(k for k in self.watch.tokens)
        problems, times = [], []
        for name in ("router", "secrets", *ROLES):
            record = found.get(name)
            if record is None:
                problems.append(f"{name}: no container")
                continue
            state = record["State"]
            want_exit = name == "secrets"
            if want_exit and (state["Status"] != "exited" or state["ExitCode"] != 0):
                problems.append(f"secrets: {state['Status']}, exit {state['ExitCode']}")
            if not want_exit and state["Status"] != "running":
                problems.append(f"{name}: {state['Status']} (exit {state['ExitCode']})")
            if record.get("RestartCount", 0):
                problems.append(f"{name}: restarted {record['RestartCount']} times")
            started = _when(state["StartedAt"])
            text = self.container_logs(record)
            mark = "listening on" if name == "router" else f"{name} up ("
            if name == "secrets":
                continue
            ups = [t for t, line in _timed_lines(text) if mark in line]
            times.append(f"{name} {ups[-1] - started:.1f} s" if ups else f"{name} ?")
        if not alive:
            missing = [r for r in ROLES if not self.watch.role_seen(r)]
            problems.append(f"no liveliness token of {', '.join(missing)} (seen: {seen})")
        self.report.check("services started", not problems,
                          "; ".join(problems) if problems else
                          "all 7 (secrets exited 0, 6 running, none restarted); from container "
                          "start to its zenoh session up: " + ", ".join(times))

    def _check_health(self, found: dict[str, dict]) -> None:
        """Every running container with a health check passes it when run: one of up to the
        check's ``Retries`` consecutive runs, as the engine's own schedule would judge it."""
        results: dict[str, str] = {}

        def one(name: str, record: dict) -> None:
            retries = int((record["Config"].get("Healthcheck") or {}).get("Retries") or 3)
            tries = []
            for _ in range(retries):
                t = time.monotonic()
                ok, out = self.engine.healthcheck(record)
                tries.append(f"{'pass' if ok else 'fail'} {time.monotonic() - t:.1f} s")
                if ok:
                    break
            results[name] = ("ok " if ok else "FAILED ") + ", ".join(tries) + f" ({out})"

        threads = [threading.Thread(target=one, args=(name, found[name])) for name in ROLES
                   if name in found and (found[name]["Config"].get("Healthcheck") or {})
                   .get("Test")]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(300)
        failed = [n for n, r in results.items() if not r.startswith("ok")]
        self.report.check("health checks", len(results) == len(ROLES) and not failed,
                          "; ".join(f"{n}: {r}" for n, r in sorted(results.items())))

    def _check_refused(self, secrets: Path) -> None:
        import zenoh

        refused, why = False, ""
        try:
            zenoh.open(client_config(secrets, self.port, None)).close()
        except zenoh.ZError as exc:
            refused, why = True, str(exc).split(" at ")[0]
        with zenoh.open(client_config(secrets, self.port, "learner")) as session:
            accepted = bool(str(session.zid()))
        self.report.check("anonymous client refused", refused and accepted,
                          f"without credentials: {'refused' if refused else 'ACCEPTED'} ({why}); "
                          f"with the learner's: {'accepted' if accepted else 'refused'}")

    def _check_image(self) -> None:
        found = self.containers()
        user = self.engine.run("image", "inspect", "--format", "{{.Config.User}}",
                               self.image).stdout.strip()
        rootless = user.split(":")[0] not in ("", "0", "root")
        # the containers of our image run as that user (compose sets no other)
        users = {r["Config"].get("User") for n, r in found.items() if n != "router"}
        read_only = {n: bool(r["HostConfig"].get("ReadonlyRootfs")) for n, r in found.items()}
        wrong = [n for n in READ_ONLY if not read_only.get(n)]
        self.report.check(
            "image", rootless and users == {user} and not wrong,
            f"{self.image} {size_mb(self.engine, self.image):.0f} MB, user {user} (containers: "
            f"{', '.join(sorted(str(u) for u in users))}); read-only "
            f"root filesystem: {', '.join(n for n in read_only if read_only[n])}; writable: "
            f"{', '.join(n for n in read_only if not read_only[n])}"
            + (f"; NOT read-only: {', '.join(wrong)}" if wrong else ""))

    def _driven_after(self, t0: float) -> list:
        return [s for t, s in self.watch.states if t > t0 and s.driver == "controller"]

    def _check_taught(self, drove: bool, gone: float) -> None:
        found = self.containers()
        teacher = found["teacher"]
        text = self.container_logs(teacher)
        acked = re.search(r"all (\d+) labels acknowledged by the learner", text)
        left = re.search(r"(\d+) unacknowledged at exit", text)
        code = teacher["State"]["ExitCode"]
        self.report.check(
            "labels acknowledged",
            code == 0 and bool(acked) and bool(left) and left.group(1) == "0",
            f"teacher exit {code}; " + (f"all {acked.group(1)} labels acknowledged"
                                        if acked else "no acknowledgement line")
            + (f", {left.group(1)} unacknowledged at exit" if left else ""))
        with self.watch.lock:
            nodes = [n.nodes for n in self.watch.notices]
            decisions = [d for d in self.watch.decisions if d.ts and d.nodes]
            after = self._driven_after(gone + 1.0)
            drivers = [d for _, d in self.watch.drivers]
        self.report.check(
            "tree grew", len(nodes) >= 2 and nodes[-1] > nodes[0] and nodes[-1] > 1,
            f"{len(nodes)} notices, nodes {nodes[0] if nodes else '-'} -> "
            f"{nodes[-1] if nodes else '-'}")
        moving = max((abs(s.vel[0]) + abs(s.vel[2]) for s in after), default=0.0)
        late = [d for d in decisions if d.nodes > 1]
        controller_log = self.container_logs(found["controller"])
        swaps = controller_log.count("swapped in a newer tree")
        self.report.check(
            "controller drove",
            drove and moving > 0.05 and bool(late) and swaps > 0 and "teacher" in drivers,
            f"drivers seen {sorted(set(drivers))}; after the teacher stopped: {len(after)} "
            f"states driven by the controller, max |vx|+|va| {moving:.2f}; {len(decisions)} "
            f"decisions, last from a {late[-1].nodes if late else 0}-node tree; "
            f"{swaps} tree swaps")

    def _check_console(self) -> None:
        text = self.container_logs(self.containers()["console"], timestamps=False)
        found = re.findall(r"console: https?://[^/\s]+/\?token=([A-Za-z0-9_-]+)", text)
        if not found:
            self.report.check("console answered", False, "no console URL in its log")
            return
        base = f"http://127.0.0.1:{self.console_port}/"
        status, size = _http(f"{base}?token={found[-1]}")
        denied, _ = _http(base)
        self.report.check("console answered", status == 200 and size > 0 and denied == 401,
                          f"GET {base}?token=... -> {status} ({size} bytes); without the "
                          f"token -> {denied}")

    def _check_numba(self) -> None:
        """The server, learner and controller containers wrote nothing into the kernel cache
        (they loaded the image's), and a one-off container shows what loading and compiling
        cost."""
        found = self.containers()
        written = {}
        for name in ("server", "learner", "controller"):
            diff = self.engine.run("diff", found[name]["Id"]).stdout.split("\n")
            written[name] = [ln for ln in diff if NUMBA_CACHE in ln]
        code = ("import time; t = time.perf_counter(); import server; "
                "from server.world import World, load_world; "
                "World(load_world(server.world_path('room'))).scans(); "
                "print(f'first cast {time.perf_counter() - t:.2f} s'); "
                "import rhbl.tree; t = time.perf_counter(); rhbl.tree.load_kernels(); "
                "print(f'tree kernels {time.perf_counter() - t:.2f} s')")
        timings = {}
        for how, extra in (("loaded", []), ("compiled", ["--read-only"])):
            run = self.engine.run("run", "--rm", *extra, "-e", "NUMBA_DEBUG_CACHE=1",
                                  "--entrypoint", "python", self.image, "-c", code,
                                  check=False, timeout=300)
            out = run.stdout + run.stderr
            cast = re.search(r"first cast ([\d.]+) s", out)
            tree = re.search(r"tree kernels ([\d.]+) s", out)
            timings[how] = (cast.group(1) if cast else "?", out.count("data loaded from"),
                            out.count("data saved to"), tree.group(1) if tree else "?",
                            len(re.findall(r"data loaded from .*/_kernels\.", out)))
        loaded, compiled = timings["loaded"], timings["compiled"]
        self.report.check(
            "numba kernels from the image",
            not any(written.values()) and loaded[1] > 0 and loaded[2] == 0 and loaded[4] > 0,
            "files written under " + NUMBA_CACHE + " by the containers: "
            + ", ".join(f"{k} {len(v)}" for k, v in written.items()) + "; a one-off "
            f"container: first laser cast {loaded[0]} s and the tree's kernels {loaded[3]} s, "
            f"loading {loaded[1]} compiled file(s) from the image ({loaded[4]} of the tree's; "
            f"{loaded[2]} compiled), {compiled[0]} s and {compiled[3]} s with a read-only root "
            f"filesystem ({compiled[1]} loaded: numba compiles then)")

    def _save_tree(self) -> None:
        learner = self.containers()["learner"]
        out = self.workdir / "tree.rhbl"
        self.engine.run("cp", f"{learner['Id']}:/data/tree.rhbl", str(out))
        from rhbl import load

        tree = load(str(out))
        _say(f"the learner's tree, copied from the data volume: {tree.node_count_} nodes, "
             f"height {tree.height_}")

    # -- ending --
    def down(self) -> None:
        if self.watch is not None:
            self.watch.close()
            self.watch = None
        found = self.containers()  # the volumes they mount, for the check below
        for name, record in found.items():
            (self.logs / f"{name}.log").write_text(self.container_logs(record))
        with self.report.step("compose down -v"):
            self.compose("down", "-v", timeout=300)
            self.up = False
        left = self.leftovers()
        self.report.check("down -v left nothing", not any(left.values()),
                          ", ".join(f"{k}: {v or 'none'}" for k, v in left.items()))

    def leftovers(self) -> dict[str, list[str]]:
        containers = self.engine.run("ps", "-a", "-q", "--filter",
                                     f"label={PROJECT_LABEL}={self.project}").stdout.split()
        networks = [n for n in self.engine.run("network", "ls", "--format",
                                               "{{.Name}}").stdout.split()
                    if n.startswith(f"{self.project}_")]
        volumes = [v for v in self.engine.run("volume", "ls", "--format",
                                              "{{.Name}}").stdout.split()
                   if v.startswith(f"{self.project}_") or v in self.volumes]
        return {"containers": containers, "networks": networks, "volumes": volumes}

    def clean(self) -> None:
        """Remove whatever of this run is still here (every path ends here)."""
        if self.watch is not None:
            with contextlib.suppress(Exception):
                self.watch.close()
        if self.up:
            with contextlib.suppress(Exception):
                self.compose("down", "-v", timeout=300)
        with contextlib.suppress(Exception):
            left = self.leftovers()
            if left["containers"]:
                self.engine.run("rm", "-f", "-v", *left["containers"], check=False)
            if left["volumes"]:
                self.engine.run("volume", "rm", "-f", *left["volumes"], check=False)
            if left["networks"]:
                self.engine.run("network", "rm", *left["networks"], check=False)
        if self.built and not self.args.keep_images:
            removed = self.engine.run("rmi", "-f", *self.built, check=False, timeout=300)
            _say(f"removed the images of this run: {', '.join(self.built)}"
                 + ("" if removed.returncode == 0 else f" ({removed.stderr.strip()})"))


def _http(url: str) -> tuple[int, int]:
    try:
        with urllib.request.urlopen(url, timeout=10) as response:  # noqa: S310 - loopback
            return response.status, len(response.read())
    except urllib.error.HTTPError as exc:
        return exc.code, 0
    except OSError:
        return 0, 0


# ---- the command --------------------------------------------------------------------------------
def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="compose_test.py", description=__doc__.splitlines()[0],
        epilog="Exit status: 0 passed, 1 a check or step failed, 2 bad arguments, 3 no engine.")
    parser.add_argument("--engine", choices=("podman", "docker"),
                        help="the container engine (default: podman if it is here, else docker)")
    parser.add_argument("--probe", action="store_true",
                        help="only say which engine would be used (exit 0) or why none (exit 3)")
    parser.add_argument("--python-image", metavar="IMAGE",
                        help="the PYTHON_IMAGE to build on (default: the Dockerfile's, pulled "
                             "if missing, else the Debian-made stand-in)")
    parser.add_argument("--image", metavar="IMAGE",
                        help="an rhbl image built already from docker/Dockerfile (default: "
                             "build one for this run)")
    parser.add_argument("--router-image", metavar="IMAGE",
                        help="the router image (default: eclipse/zenoh, pulled if missing, "
                             "else the stand-in)")
    parser.add_argument("--teach-seconds", type=_positive, default=45,
                        help="RHBL_TEACH_SECONDS: how long the teacher teaches (45)")
    parser.add_argument("--demonstrate-seconds", type=_positive, default=15,
                        help="RHBL_DEMONSTRATE_SECONDS: demonstration before correcting (15)")
    parser.add_argument("--start-timeout", type=_positive, default=180,
                        help="seconds for every role to come up (180)")
    parser.add_argument("--pull-timeout", type=_positive, default=120,
                        help="seconds for an image pull to answer (120)")
    parser.add_argument("--debian-mirror", default="http://deb.debian.org/debian",
                        help="Debian mirror for the base image (%(default)s)")
    parser.add_argument("--debian-security", default="http://deb.debian.org/debian-security",
                        help="Debian security mirror for the base image (%(default)s)")
    parser.add_argument("--workdir", type=Path,
                        help="logs, secrets and the learned tree go here (default: a "
                             "temporary folder, removed when every check passed)")
    parser.add_argument("--keep-images", action="store_true",
                        help="keep the rhbl and router images this run built")
    return parser


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be positive: {text!r}")
    return int(value) if value.is_integer() else value


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.demonstrate_seconds >= args.teach_seconds:
        print("compose_test.py: --demonstrate-seconds must be less than --teach-seconds",
              file=sys.stderr)
        return EXIT_USAGE
    engine = find_engine(args.engine)
    if isinstance(engine, str):
        print(f"compose-test: {engine}", file=sys.stderr)
        return EXIT_NO_ENGINE
    compose = " ".join(Path(engine.compose[0]).name if i == 0 else a
                       for i, a in enumerate(engine.compose))
    version = engine.run("--version", check=False).stdout.strip()
    _say(f"engine: {version} with {compose}"
         + (f" (CONTAINERS_CONF={engine.env['CONTAINERS_CONF']})"
            if "CONTAINERS_CONF" in engine.env else ""))
    if args.probe:
        return EXIT_OK

    def stop(signum, _frame):
        raise SystemExit(f"compose-test: stopped by signal {signum}")

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, stop)
    workdir = args.workdir or Path(tempfile.mkdtemp(prefix="rhbl-compose-test-"))
    workdir.mkdir(parents=True, exist_ok=True)
    scenario = Scenario(engine, args, workdir)
    try:
        scenario.images()
        scenario.start()
        scenario.run_checks()
        scenario.down()
    except (StepFailed, subprocess.TimeoutExpired) as exc:
        scenario.report.check("steps", False, str(exc))
    except Exception as exc:  # noqa: BLE001 - reported as a failed step, then cleaned up
        if os.environ.get("RHBL_DEBUG"):
            import traceback

            traceback.print_exc()
        scenario.report.check("steps", False, f"{type(exc).__name__}: {exc}")
    finally:
        with scenario.report.step("clean up"):
            scenario.clean()
    print(scenario.report.summary(), flush=True)
    if scenario.report.passed and args.workdir is None:
        shutil.rmtree(workdir, ignore_errors=True)
    else:
        _say(f"logs: {scenario.logs}")
    return EXIT_OK if scenario.report.passed else EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
