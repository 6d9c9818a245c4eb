"""``rhbl demo --by-hand``: teach the robot yourself at the console's page.

The same rendezvous as ``rhbl demo`` (a zenoh router on a free loopback port; every child a
client), and the processes a person needs to teach by hand, each a separate OS process:

1. ``rhbl learner --behaviour B`` (the behaviour's perception; its default ``--teacher
   auto``: the page's labels are a person's, so the new tree learns by the person rule; the
   tree and its journal go into the output folder), ``rhbl server`` (the world, in real time) and
   ``rhbl console --behaviour B`` (the page that drives and teaches, showing the behaviour's
   instructions and success rule; its URL printed; the terminal prints the instructions too).
   ``B`` is ``--behaviour`` (default wall following), its first teaching world the default
   ``--world``. You **demonstrate**
   for ``--demonstrate`` seconds (wall time; Enter at the terminal ends it sooner);
2. ``rhbl controller --from-learner --follow`` then drives the learner's newest tree (its loop
   guard on), and you **correct** in the page's correct mode (C) for ``--correct`` seconds
   (Enter or Ctrl-C ends it sooner): take over where the robot goes wrong or where the page
   says "the robot is stuck here: show it the way";
3. the processes stop in order (the controller, the console once the learner acknowledged
   every label, the learner with its final snapshot, the server), and ``rhbl evaluate`` drives
   the tree from the world's start poses as the controller would (a tree taught by hand
   through its guard) (``--starts``, ``--drive-seconds``): its table
   is printed, with the commands to evaluate it again in other rooms. ``--record`` records
   the session (every bus message) to retrain it later (``rhbl train --from-recording``).

Children are stopped by PID on every exit path; the exit status is non-zero if one failed.
docs/teaching.md says how to teach well.
"""

from __future__ import annotations

import select
import subprocess
import sys
import time

from client.behaviour.given import as_argument
from lab.demo_run import Child, Demo, DemoError

__all__ = ["ByHand", "NOT_BY_HAND", "check_args"]

# the demo's options that drive its scripted teacher: refused with --by-hand, by name
NOT_BY_HAND = {"scenario": None, "teach_seconds": None, "rounds": None,
               "round_seconds": None, "style": "reactive", "speedup": None, "seed": 0}


def check_args(args) -> None:
    """ValueError naming the options that do not apply to ``--by-hand``."""
    bad = [f"--{k.replace('_', '-')}" for k, default in NOT_BY_HAND.items()
           if getattr(args, k) != default]
    if bad:
        raise ValueError(f"--by-hand: {', '.join(bad)} drive the scripted teacher's demo and do "
                         f"not apply (you teach; --behaviour, --world, --out, --console, "
                         f"--demonstrate, --correct, --starts, --drive-seconds and --record do)")


class ByHand(Demo):
    """The processes of teaching by hand (see the module)."""

    def __init__(self, args):
        check_args(args)
        # the world: --world, else the behaviour's first teaching world (wall following's:
        # the room the person models of docs/teaching.md taught in)
        if args.out is None:
            import datetime as _dt
            from pathlib import Path

            stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
            args.out = str(Path("rhbl-out") / f"{stamp}-by-hand")
        super().__init__(args)
        self.address = args.console or "127.0.0.1:8080"

    def instructions(self) -> str:
        """What the person teaches: the behaviour's instructions (else its summary), indented."""
        text = self.behaviour.instructions or self.behaviour.summary
        return "\n".join("   " + line for line in text.splitlines())

    def wait(self, seconds: float, what: str, *cs: Child) -> str:
        """``seconds`` of wall time, or Enter at a terminal; the processes watched meanwhile.
        How it ended: ``time`` or ``enter``."""
        tty = sys.stdin is not None and sys.stdin.isatty()
        end = time.monotonic() + seconds
        next_note = time.monotonic() + 30.0
        while (left := end - time.monotonic()) > 0:
            self.check_alive(*cs)
            if tty:
                ready, _, _ = select.select([sys.stdin], [], [], min(0.2, left))
                if ready:
                    sys.stdin.readline()
                    return "enter"
            else:
                time.sleep(min(0.2, left))
            if time.monotonic() >= next_note:
                next_note += 30.0
                self.say(f"{what}: {max(0.0, end - time.monotonic()):.0f} s left")
        return "time"

    def run(self) -> int:
        import zenoh

        from process.session import make_config

        args = self.args
        self.say(f"rhbl demo --by-hand: world {self.spec.name}, output {self.out}")
        from client.recording.record import demo_recording, say_demo_recording
        from client.recording.tap import BusTap

        with zenoh.open(make_config(mode="router", listen=[self.endpoint])) as session:
            self.session = session
            # --record: every bus message of the session (to retrain it: rhbl train
            # --from-recording OUT/run.mcap ..., docs/recording.md)
            writer = demo_recording(args.record, self.out, self.say)
            tap = None if writer is None else BusTap(session, [writer], world=True)
            try:
                return self.phases(args)
            finally:
                if tap is not None:
                    tap.close()
                    say_demo_recording(tap, writer, self.say)

    def phases(self, args) -> int:
        """The phases (see the module); the exit status."""
        b = as_argument(self.behaviour)  # its perception for the learner, its words on the page
        learner = self.child("learner", "learner", "--behaviour", b, "--out",
                             str(self.tree), "--snapshot-every", "1", "--wait-server", "60")
        self.wait_token("learner", learner)  # no label before the learner listens
        server = self.child("server", "server", "--mode", "client", "--world",
                            str(self.spec.path))
        console = self.child("console", "console", "--http", self.address, "--behaviour", b)
        if not console.wait_for_line("console: ", timeout=30.0):
            self.check_alive(console)
            raise DemoError(f"the console did not start within 30 s:\n{console.tail()}")
        url = next(ln.split(" ", 1)[1] for ln in console.lines
                   if ln.startswith("console: "))
        print(f"console: {url}", flush=True)
        print(f"1. demonstrate ({args.demonstrate:g} s; Enter here ends it sooner): open the "
              "URL, press Home (the robot at its start pose) and hold the arrow keys; letting "
              f"go stops the robot. What to teach ({self.name}, also on the page):\n"
              f"{self.instructions()}", flush=True)
        how = self.wait(args.demonstrate, "demonstrating", learner, server, console)
        self.say(f"demonstration over ({'Enter' if how == 'enter' else 'time'})")
        controller = self.child("controller", "controller", "--from-learner", "--follow",
                                "--wait-tree", "60", *self.again)
        print(f"2. correct ({args.correct:g} s; Enter or Ctrl-C here ends it sooner): the "
              "controller drives the learned tree now. Press C on the page (correct mode): "
              "keep your hands off while it does well, take over with the keys where it goes "
              "wrong or where the page says \"the robot is stuck here: show it the way\", "
              "then let go.", flush=True)
        try:
            how = self.wait(args.correct, "correcting", learner, server, console, controller)
            self.say(f"correcting over ({'Enter' if how == 'enter' else 'time'})")
        except KeyboardInterrupt:
            self.say("correcting over (Ctrl-C)")
        return self.finish(learner, server, console, controller)

    def finish(self, learner: Child, server: Child, console: Child, controller: Child) -> int:
        """Stop in order, then the tree from the world's start poses (``rhbl evaluate``)."""
        from client.journal import Journal, journal_path

        rcs = {}
        for c in (controller, console, learner, server):  # the console drains its labels
            rcs[c.name] = c.stop(timeout=60 if c in (console, learner) else 10)
        bad = {n: rc for n, rc in rcs.items() if rc not in (0, -2, 130)}
        if bad:
            raise DemoError(f"processes failed: {bad}")
        if not self.tree.exists():
            print("no tree: the learner got no label (nothing was demonstrated)", flush=True)
            return 1
        with Journal.open(journal_path(self.tree), readonly=True) as j:
            rule = (j.header["meta"].get("learning") or {}).get("rule") or "script"
            labels = len(list(j.standing()))
        self.say(f"the tree: {self.tree} ({labels} labels standing, the {rule} rule)")
        argv = [*_evaluate_argv(self), "--behaviour", as_argument(self.behaviour), "--world",
                str(self.spec.path), "--tree", str(self.tree)]
        self.say(f"3. the tree from the world's start poses: rhbl {' '.join(argv[3:])}")
        done = subprocess.run(argv, capture_output=True, text=True, timeout=3600)
        print(done.stdout, end="", flush=True)
        if done.returncode != 0:
            raise DemoError(f"rhbl evaluate exited {done.returncode}: {done.stderr[-1000:]}")
        held = self.behaviour.held_out
        if held:
            print(f"evaluate it in rooms it never saw: rhbl evaluate --behaviour "
                  f"{as_argument(self.behaviour)} --world {held[0]} --tree {self.tree}   "
                  "(docs/teaching.md)", flush=True)
        print(f"output: {self.out}  (tree.rhbl, tree.rhbl.journal, logs/)", flush=True)
        return 0


def _evaluate_argv(demo: ByHand) -> list[str]:
    from lab.children import rhbl_argv

    argv = rhbl_argv("evaluate")
    if demo.args.starts:
        argv += ["--episodes", str(demo.args.starts)]
    if demo.args.drive_seconds:
        argv += ["--seconds", f"{demo.args.drive_seconds:g}"]
    return argv
