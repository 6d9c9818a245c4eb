// rhbl console: draws what the console process forwards from the bus and sends the person's
// commands back. Plain JS, no framework, no network beyond the page's own WebSocket.
// Messages: client/roles/console/app.py (docstring). Exposed for tests and people: #pose data-x/y/yaw
// (the pose drawn last), #hold data-holder, #tree data-nodes/vectors, #fps data-fps/frames,
// #learner data-up/seq, #labels data-given/held/waiting/withdrawn, #agreement data-value/n,
// #trouble data-markers/loops/stalls/collisions, #stuck data-why, #episode data-n/state,
// #asks data-n/elsewhere/asking (the places the tree's refinement asks to be shown; each
// li data-n/shown and its "show me here" button),
// #clock data-t, #view data-beacons/seen (the beacons drawn, the ids of those the robot sees);
// and window.rhbl.view(): what the page shows now, read-only (the robot as drawn, the walls,
// the goal, the beacons and those seen, the mode, who drives, the action executed, the scan
// displayed,
// the clock).
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("view");
const g = canvas.getContext("2d");

const S = {
  ws: null, page: null, robot: null, viewOnly: false, mode: "demonstrate",
  world: null, state: null, scan: null, fiducial: null, notice: null, decision: null, control: null,
  cmds: {}, trail: [], teach: null, dragging: null,
  view: { cx: 0, cy: 0, scale: 50, fitted: false }, follow: false,
  keys: new Set(), pad: null, gamepad: null, sent: null, sentScan: -1,
  frames: 0, fpsT0: performance.now(), fpsN: 0,
};

// ---- the connection --------------------------------------------------------------------
function connect() {
  const proto = location.protocol === "https:" ? "wss:" : "ws:";
  const token = new URLSearchParams(location.search).get("token");
  const url = `${proto}//${location.host}/ws${token ? "?token=" + encodeURIComponent(token) : ""}`;
  const ws = new WebSocket(url);
  S.ws = ws;
  ws.onopen = () => { setLink(true); send({ t: "mode", mode: S.mode }); };
  ws.onmessage = (ev) => { try { receive(JSON.parse(ev.data)); } catch (e) { showError(String(e)); } };
  ws.onclose = (ev) => {
    setLink(false);
    S.keys.clear(); S.pad = null; S.sent = null; // nothing is sent on a dead link anyway
    if (ev.code === 1013) { // refused (too many pages): say why, try again less often
      $("link").textContent = `refused: ${ev.reason || "the console is busy"}`;
      setTimeout(connect, 5000);
      return;
    }
    setTimeout(connect, 1000);
  };
  ws.onerror = () => {}; // onclose follows
}

function setLink(up) {
  $("link").textContent = up ? "connected" : "disconnected: retrying";
  $("link").className = up ? "ok" : "bad";
  $("link").dataset.state = up ? "open" : "closed";
}

function send(msg) {
  if (S.ws && S.ws.readyState === WebSocket.OPEN) S.ws.send(JSON.stringify(msg));
}

function showError(text) {
  $("error").textContent = text;
  clearTimeout(showError.timer);
  showError.timer = setTimeout(() => { $("error").textContent = ""; }, 5000);
}

function receive(m) {
  if (m.robot !== undefined && S.robot !== null && m.t !== "hello" && m.robot !== S.robot) return;
  switch (m.t) {
    case "hello": {
      const want = S.robot; // a reconnection keeps watching the robot chosen before
      S.page = m.page; S.robot = m.robot; S.viewOnly = m.view_only;
      setRobots(m.robots.length ? m.robots : [m.robot]);
      if (want && want !== m.robot) { S.robot = want; $("robot").value = want; send({ t: "view", robot: want }); }
      if (m.behaviour) showBehaviour(m.behaviour);
      if (m.view_only) {
        for (const el of document.querySelectorAll("#pad button, #modes input, #take, #episodes button, #episodes input, #place button, #place select")) el.disabled = true;
        $("hold").textContent = "view-only console: watching";
      }
      break;
    }
    case "robots": setRobots(m.robots); break;
    case "world":
      S.world = m; S.view.fitted = false; canvas.dataset.walls = m.walls.length; setStarts();
      if (m.behaviour) showBehaviour(m.behaviour);
      break;
    case "state":
      S.state = m;
      { // a jump (a teleport) starts a new piece of trail
        const last = S.trail[S.trail.length - 1];
        const who = whoDrives(m.driver);
        if (last && Math.hypot(m.pose[0] - last[0], m.pose[1] - last[1]) > 1.0) S.trail.push(null);
        S.trail.push([m.pose[0], m.pose[1], who]);
      }
      if (S.trail.length > 2000) S.trail.splice(0, S.trail.length - 2000);
      break;
    case "scan":
      S.scan = m;
      if (S.sent) { send({ t: "drive", action: S.sent, scan_id: m.id }); S.sentScan = m.id; }
      break;
    case "fiducial": S.fiducial = m; break;
    case "notice": S.notice = m; break;
    case "decision": S.decision = m; break;
    case "cmd": S.cmds[m.source] = m; break;
    case "control": S.control = m; showHold(); break;
    case "teach": S.teach = m; showTeach(); showHold(); break;
    case "placed":
      if (m.reset) S.trail = [];
      else S.trail.push(null);
      showInfo(`the robot is at ${m.where}`);
      break;
    case "info": showInfo(m.info); break;
    case "error": showError(m.error); break;
  }
}

// the behaviour taught (rhbl console --behaviour, else the world's): what to teach, and
// the rule the learned robot is judged by
function showBehaviour(b) {
  $("behaviour").hidden = false;
  $("behaviour").dataset.name = b.name;
  $("behaviour-name").textContent = b.name;
  $("behaviour-summary").textContent = b.summary;
  $("instructions").textContent = b.instructions || b.summary;
  $("rule").textContent = `success: ${b.rule}`;
}

function showInfo(text) {
  $("info").textContent = text;
  clearTimeout(showInfo.timer);
  showInfo.timer = setTimeout(() => { $("info").textContent = ""; }, 6000);
}

// who drives, as the colours say: "me" (a teacher: the person), "controller", "" (nobody)
function whoDrives(driver) {
  return !driver ? "" : driver.startsWith("teacher") ? "teacher"
    : driver.startsWith("controller") ? "controller" : "other";
}
const COLOURS = { teacher: "#e8a33d", controller: "#4a90d9", other: "#8a6d3b", "": "#999" };
const MARKS = { loop: "#9b3fd5", stall: "#16a39a", collision: "#c2185b" };

function setStarts() {
  const sel = $("starts"), starts = S.world ? S.world.starts || [] : [];
  sel.innerHTML = "";
  starts.forEach((p, i) => sel.add(new Option(
    `start ${i + 1}: ${p[0].toFixed(1)}, ${p[1].toFixed(1)}, ${(p[2] * 180 / Math.PI).toFixed(0)}\u00b0`,
    String(i), false, i === (S.world.start || 0))));
  $("go").disabled = !starts.length || S.viewOnly;
}

function plural(n, one, many) { return `${n} ${n === 1 ? one : many || one + "s"}`; }

// the learner, the labels, the episode, the agreement and where the robot got into trouble
function showTeach() {
  const m = S.teach;
  if (!m) return;
  const L = $("learner"), lab = $("labels");
  const up = m.learner ? m.learner.up : null;
  L.dataset.seq = m.seq;
  L.dataset.up = up === null ? "" : up ? "1" : "0";
  const b = m.labels;
  L.textContent = up === null ? "learner: unknown" : up ? "a learner is listening"
    : "no learner is up: your labels are kept and sent once one is";
  L.className = up ? "ok" : up === null ? "" : "warn";
  if (b) {
    lab.dataset.given = b.given; lab.dataset.held = b.held; lab.dataset.waiting = b.waiting;
    lab.dataset.withdrawn = b.withdrawn; lab.dataset.refused = b.refused || 0;
    lab.textContent = `labels: ${b.given} given, ${b.held} held by the learner, ${b.waiting} waiting`
      + (b.withdrawn ? `, ${b.withdrawn} withdrawn` : "")
      + (b.refused ? `, ${b.refused} refused by the learner as bad input` : "")
      + (b.withdrawals_waiting ? ` (${plural(b.withdrawals_waiting, "withdrawal")} not yet acknowledged)` : "");
    lab.className = b.waiting >= b.cap ? "bad" : b.waiting > 50 && !up ? "warn" : "";
  } else {
    lab.textContent = "labels: none given yet";
  }
  const A = $("agreement");
  A.dataset.value = m.agreement === null ? "" : m.agreement; A.dataset.n = m.scored;
  A.textContent = m.agreement === null
    ? (m.tree ? "agreement: no key scored yet (drive to see)" : "agreement: no tree yet")
    : `the tree agrees with ${(100 * m.agreement).toFixed(0)}% of your last ${plural(m.scored, "key")} (${m.window.toFixed(0)} s)`;
  A.className = m.agreement === null ? "" : m.agreement >= 0.8 ? "ok" : m.agreement >= 0.5 ? "warn" : "bad";
  const count = { loop: 0, stall: 0, collision: 0 };
  for (const k of m.markers) count[k.kind] = (count[k.kind] || 0) + k.count;
  const T = $("trouble");
  T.dataset.markers = m.markers.length; T.dataset.loops = count.loop;
  T.dataset.stalls = count.stall; T.dataset.collisions = count.collision;
  T.textContent = m.markers.length
    ? `on the map: ${plural(count.loop, "loop")}, ${plural(count.stall, "stall")}, ${plural(count.collision, "collision")}`
    : "the learned robot has not looped, stalled or collided";
  const E = $("episode"), eps = m.episodes || [], cur = eps.length ? eps[eps.length - 1] : null;
  E.dataset.n = cur ? cur.n : ""; E.dataset.state = cur ? cur.state : "";
  E.dataset.labels = cur ? cur.labels : "";
  E.textContent = !cur ? "none yet: your first key starts one"
    : `episode ${cur.n} ${cur.state}: ${plural(cur.labels, "label")}`
      + (eps.length > 1 ? ` (${plural(eps.filter((e) => e.state !== "discarded").length, "episode")} kept)` : "");
  $("record").firstChild.textContent = m.episode !== null ? "stop " : "record ";
  showAsks(m);
  const G = $("yourgoal"), g = m.goals;
  $("goals").hidden = !g;
  G.dataset.beacon = g ? g.beacon : ""; G.dataset.visit = g ? g.visit : "";
  G.textContent = g ? g.text : "-";
  const stuck = $("stuck");
  const show = m.stuck && S.mode !== "demonstrate";
  stuck.hidden = !show;
  stuck.dataset.why = show ? m.stuck.why : "";
  if (show) {
    stuck.textContent = S.mode === "correct"
      ? `the robot is stuck here (${STUCK[m.stuck.why] || m.stuck.why}): show it the way`
      : `the robot is stuck here (${m.stuck.why}): switch to correct (C) to show it the way`;
  }
}

// where the tree's refinement by practice asks the person to show the way (rhbl refine)
const ASK_WHY = { collision: "it collided", band: "it left the wall's band", failed: "it failed" };
function showAsks(m) {
  const asks = m.asks || [], sec = $("asks"), list = $("asks-list");
  sec.hidden = !asks.length && !m.asks_elsewhere;
  sec.dataset.n = asks.length; sec.dataset.elsewhere = m.asks_elsewhere || 0;
  sec.dataset.asking = m.asking || "";
  const key = JSON.stringify(asks) + (m.asking || "");
  if (list.dataset.key !== key) {
    list.dataset.key = key;
    list.innerHTML = "";
    for (const a of asks) {
      const li = document.createElement("li");
      li.dataset.n = a.n; li.dataset.shown = a.shown;
      const [x, y, yaw] = a.pose;
      li.append(`${ASK_WHY[a.why] || a.why} after (${x.toFixed(2)}, ${y.toFixed(2)}), heading ${(yaw * 180 / Math.PI).toFixed(0)}\u00b0`
        + (a.shown ? `: shown, ${plural(a.shown, "label")}` : "") + (m.asking === a.n ? " (the robot is here)" : "") + " ");
      const b = document.createElement("button");
      b.textContent = "show me here"; b.title = "put the robot here; then correct it (C) and show it the way";
      b.onclick = () => { release(); send({ t: "place", ask: a.n }); };
      li.append(b);
      list.append(li);
    }
  }
  $("asks-elsewhere").textContent = m.asks_elsewhere
    ? `${plural(m.asks_elsewhere, "more ask")} in practice worlds not shown here (scaled copies or other worlds)` : "";
}

// why the learned robot is stuck, as the panel says it
const STUCK = {
  loop: "it turns left and right in a loop",
  guard: "it would turn left and right in a loop: the controller's loop guard keeps it turning one way",
  stall: "it hardly moves",
};

function setRobots(names) {
  const sel = $("robot");
  const have = Array.from(sel.options).map((o) => o.value).join();
  if (have === names.join()) return;
  sel.innerHTML = "";
  for (const n of names) sel.add(new Option(n, n, false, n === S.robot));
}

$("robot").onchange = (e) => {
  release();
  S.robot = e.target.value; S.world = null; S.state = null; S.scan = null; S.fiducial = null; S.notice = null;
  S.decision = null; S.control = null; S.cmds = {}; S.trail = [];
  send({ t: "view", robot: S.robot });
};

for (const r of document.querySelectorAll("#modes input")) {
  r.onchange = () => { S.mode = r.value; release(); send({ t: "mode", mode: S.mode }); showTeach(); showHold(); };
}

function setMode(mode) {
  if (S.viewOnly || mode === S.mode) return;
  const input = document.querySelector(`#modes input[value="${mode}"]`);
  input.checked = true;
  input.onchange();
}

// ---- episodes, undo, where the robot is ----------------------------------------------------
function episode(what) { release(); send({ t: "episode", do: what }); }
function undo() {
  const s = Number($("undo-seconds").value);
  release(); send({ t: "undo", seconds: s });
}
function placeAt(i) {
  if (!S.world || !(S.world.starts || []).length) { showError("the world gives no start poses"); return; }
  if (i >= S.world.starts.length) { showError(`the world has ${S.world.starts.length} start poses`); return; }
  $("starts").value = String(i);
  release(); send({ t: "place", start: i });
}
function reset() { release(); send({ t: "reset" }); }
$("record").onclick = () => SHORTCUTS.r();
$("discard").onclick = () => episode("discard");
$("rerecord").onclick = () => episode("rerecord");
$("undo").onclick = undo;
$("go").onclick = () => placeAt(Number($("starts").value));
$("reset").onclick = reset;
$("take").onclick = () => send({ t: "take" });
$("reached").onclick = () => reached();
$("follow").onchange = (e) => { S.follow = e.target.checked; };

function showHold() {
  const c = S.control, el = $("hold");
  if (S.viewOnly) return;
  let who = "none";
  if (c && c.holder !== null) who = c.holder === S.page ? "me" : "other";
  el.dataset.holder = who;
  const t = S.teach, nobody = t && t.learner && !t.learner.up;
  el.textContent = who === "me" ? `you hold the robot (${c.holder_mode})`
    + (nobody ? `: no learner is up, your ${t.labels ? t.labels.waiting : 0} labels wait for one` : "")
    : who === "other" ? `page #${c.holder} holds the robot: you watch`
    : S.mode === "watch" ? "watching" : "nobody holds the robot: press a key to drive";
  $("take").hidden = who !== "other" || S.mode === "watch";
}

// ---- driving: keys, buttons, gamepad -------------------------------------------------------
const KEYS = { ArrowUp: "up", w: "up", W: "up", ArrowLeft: "left", a: "left", A: "left",
  ArrowRight: "right", d: "right", D: "right" };

function actionOf(up, left, right) {
  if (left && right) left = right = false;
  if (up) return left ? "fwd-left" : right ? "fwd-right" : "fwd";
  return left ? "rot-left" : right ? "rot-right" : null;
}

function wanted() {
  if (S.pad) return S.pad;
  const k = S.keys, gp = S.gamepad || {};
  return actionOf(k.has("up") || gp.up, k.has("left") || gp.left, k.has("right") || gp.right);
}

// Send the action wanted now: at once on a change, then with every new scan while it is held.
function update() {
  const a = S.viewOnly || S.mode === "watch" ? null : wanted();
  if (a === S.sent) return;
  S.sent = a;
  $("mine").textContent = a || "-";
  for (const b of document.querySelectorAll("#pad button")) b.classList.toggle("on", b.dataset.action === a);
  if (a && S.scan) { send({ t: "drive", action: a, scan_id: S.scan.id }); S.sentScan = S.scan.id; }
  else if (!a) send({ t: "release" });
}

function release() { S.keys.clear(); S.pad = null; S.gamepad = null; update(); }

// goals in order: the goal you pursue is reached (the next label says so and is for the next)
function reached() { if (S.teach && S.teach.goals) send({ t: "reached" }); }

// the shortcuts (the page's "keys" table and docs/console.md say the same)
const SHORTCUTS = {
  t: () => setMode("demonstrate"), v: () => setMode("watch"), c: () => setMode("correct"),
  r: () => episode(S.teach && S.teach.episode !== null ? "stop" : "start"),
  x: () => episode("discard"), e: () => episode("rerecord"),
  z: undo, Backspace: undo, Home: reset, g: reached,
  f: () => { S.follow = !S.follow; $("follow").checked = S.follow; },
};

addEventListener("keydown", (e) => {
  const tag = e.target.tagName;
  if (tag === "SELECT" || tag === "INPUT" || tag === "TEXTAREA") return;
  if (e.key === " " || e.key === "Escape") { e.preventDefault(); release(); return; }
  const k = KEYS[e.key];
  if (!k) {
    if (e.ctrlKey || e.metaKey || e.altKey) return;
    const name = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    const fn = SHORTCUTS[name];
    if (fn) { e.preventDefault(); if (!e.repeat) fn(); return; }
    if (/^[1-9]$/.test(e.key)) { e.preventDefault(); if (!e.repeat) placeAt(Number(e.key) - 1); }
    return;
  }
  e.preventDefault();
  if (!e.repeat) { S.keys.add(k); update(); }
});
addEventListener("keyup", (e) => {
  const k = KEYS[e.key];
  if (k) { S.keys.delete(k); update(); }
});
// the robot never keeps moving on a key the page can no longer see released
addEventListener("blur", release);
document.addEventListener("visibilitychange", () => { if (document.hidden) release(); });
addEventListener("pagehide", release);

for (const b of document.querySelectorAll("#pad button")) {
  const a = b.dataset.action;
  b.addEventListener("pointerdown", (e) => {
    e.preventDefault();
    if (a === "release") { release(); return; }
    S.pad = a; b.setPointerCapture(e.pointerId); update();
  });
  for (const ev of ["pointerup", "pointercancel", "lostpointercapture"]) {
    b.addEventListener(ev, () => { if (S.pad === a) { S.pad = null; update(); } });
  }
}

function pollGamepad() {
  const pads = navigator.getGamepads ? navigator.getGamepads() : [];
  const p = Array.from(pads || []).find((x) => x && x.connected);
  if (!p) { if (S.gamepad) { S.gamepad = null; update(); } return; }
  const ax = p.axes || [], bt = p.buttons || [];
  const on = (i) => bt[i] && bt[i].pressed;
  const gp = { up: (ax[1] || 0) < -0.5 || on(12), left: (ax[0] || 0) < -0.5 || on(14),
    right: (ax[0] || 0) > 0.5 || on(15) };
  if (on(1)) { release(); return; } // B: release
  const prev = S.gamepad || {};
  if (gp.up !== !!prev.up || gp.left !== !!prev.left || gp.right !== !!prev.right) {
    S.gamepad = gp; update();
  }
}

// ---- zoom, pan, follow ----------------------------------------------------------------------
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  const f = Math.exp(-e.deltaY * 0.0015);
  const before = toWorld(e.offsetX, e.offsetY);
  S.view.scale = Math.min(800, Math.max(5, S.view.scale * f));
  const after = toWorld(e.offsetX, e.offsetY);
  S.view.cx += before[0] - after[0]; S.view.cy += before[1] - after[1];
}, { passive: false });
// drag the map to pan; drag the robot's body to move it, its nose to turn it (sent on release)
let drag = null;
function robotPose() { return S.state ? S.state.pose : S.scan ? S.scan.pose : null; }
canvas.addEventListener("pointerdown", (e) => {
  canvas.focus();
  const p = robotPose(), [wx, wy] = toWorld(e.offsetX, e.offsetY);
  const mayMove = p && !S.viewOnly && S.mode !== "watch";
  if (mayMove) {
    const nose = [p[0] + 0.3 * Math.cos(p[2]), p[1] + 0.3 * Math.sin(p[2])];
    const grab = Math.max(0.12, 8 / S.view.scale);
    const how = Math.hypot(wx - nose[0], wy - nose[1]) < grab ? "turn"
      : Math.hypot(wx - p[0], wy - p[1]) < 0.25 + grab / 2 ? "move" : null;
    if (how) {
      release();
      S.dragging = { how, pose: [p[0], p[1], p[2]], dx: wx - p[0], dy: wy - p[1] };
      canvas.setPointerCapture(e.pointerId);
      return;
    }
  }
  drag = [e.offsetX, e.offsetY];
});
canvas.addEventListener("pointermove", (e) => {
  const d = S.dragging;
  if (d) {
    const [wx, wy] = toWorld(e.offsetX, e.offsetY);
    if (d.how === "move") { d.pose[0] = wx - d.dx; d.pose[1] = wy - d.dy; }
    else d.pose[2] = Math.atan2(wy - d.pose[1], wx - d.pose[0]);
    return;
  }
  if (!drag) return;
  const dx = e.offsetX - drag[0], dy = e.offsetY - drag[1];
  if (Math.abs(dx) + Math.abs(dy) < 3) return;
  S.view.cx -= dx / S.view.scale; S.view.cy += dy / S.view.scale; drag = [e.offsetX, e.offsetY];
  if (S.follow) { S.follow = false; $("follow").checked = false; }
});
addEventListener("pointerup", () => {
  drag = null;
  const d = S.dragging;
  if (d) {
    S.dragging = null;
    send({ t: "place", pose: d.pose.map((v) => Math.round(v * 1000) / 1000) });
  }
});

function toWorld(px, py) {
  const w = canvas.clientWidth, h = canvas.clientHeight, v = S.view;
  return [v.cx + (px - w / 2) / v.scale, v.cy - (py - h / 2) / v.scale];
}

function fit() {
  const walls = S.world ? S.world.walls : [];
  if (!walls.length) return;
  let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
  for (const [a, b, c, d] of walls) {
    x0 = Math.min(x0, a, c); x1 = Math.max(x1, a, c); y0 = Math.min(y0, b, d); y1 = Math.max(y1, b, d);
  }
  S.view.cx = (x0 + x1) / 2; S.view.cy = (y0 + y1) / 2;
  S.view.scale = 0.9 * Math.min(canvas.clientWidth / (x1 - x0 || 1), canvas.clientHeight / (y1 - y0 || 1));
  S.view.fitted = true;
}

// ---- drawing --------------------------------------------------------------------------------
function draw() {
  const dpr = window.devicePixelRatio || 1, w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(h * dpr)) {
    canvas.width = Math.round(w * dpr); canvas.height = Math.round(h * dpr);
  }
  if (!S.view.fitted) fit();
  const pose = S.state ? S.state.pose : S.scan ? S.scan.pose : null;
  if (S.follow && pose) { S.view.cx = pose[0]; S.view.cy = pose[1]; }
  const v = S.view;
  if (canvas.dataset.scale !== v.scale.toFixed(2)) canvas.dataset.scale = v.scale.toFixed(2);
  canvas.dataset.cx = v.cx.toFixed(3); canvas.dataset.cy = v.cy.toFixed(3);
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  g.clearRect(0, 0, w, h);
  g.setTransform(dpr * v.scale, 0, 0, -dpr * v.scale, dpr * (w / 2 - v.cx * v.scale), dpr * (h / 2 + v.cy * v.scale));
  const px = 1 / v.scale; // one screen pixel in metres
  grid(w, h, px);
  if (S.world) {
    if (S.world.goal) {
      const [gx, gy, gr] = S.world.goal;
      g.fillStyle = "rgba(40,170,60,0.25)"; g.beginPath(); g.arc(gx, gy, gr, 0, 2 * Math.PI); g.fill();
    }
    g.strokeStyle = "#333"; g.lineWidth = 0.04; g.lineCap = "round"; g.beginPath();
    for (const [a, b, c, d] of S.world.walls) { g.moveTo(a, b); g.lineTo(c, d); }
    g.stroke();
  }
  if (S.world) startsDrawn(px);
  beacons(px, S.state ? S.state.pose : S.scan ? S.scan.pose : null);
  trail(px);
  const sc = S.scan;
  if (sc) {
    const [x, y, yaw] = sc.pose, n = sc.ranges.length;
    g.fillStyle = "rgba(230,60,40,0.12)"; g.beginPath(); g.moveTo(x, y);
    const hits = [];
    for (let i = 0; i < n; i++) {
      const a = yaw + sc.min_angle + i * sc.resolution, r = sc.ranges[i];
      const ex = x + r * Math.cos(a), ey = y + r * Math.sin(a);
      g.lineTo(ex, ey);
      if (r < sc.max_range) hits.push(ex, ey);
    }
    g.closePath(); g.fill();
    g.fillStyle = "rgb(220,40,30)";
    const d = 3 * px;
    for (let i = 0; i < hits.length; i += 2) g.fillRect(hits[i] - d / 2, hits[i + 1] - d / 2, d, d);
  }
  if (S.dragging) { // where it will be put
    const [x, y, yaw] = S.dragging.pose;
    g.setLineDash([4 * px, 3 * px]); g.strokeStyle = "#222"; g.lineWidth = 1.5 * px;
    g.beginPath(); g.arc(x, y, 0.25, 0, 2 * Math.PI); g.stroke();
    g.beginPath(); g.moveTo(x, y); g.lineTo(x + 0.3 * Math.cos(yaw), y + 0.3 * Math.sin(yaw)); g.stroke();
    g.setLineDash([]);
  }
  if (pose) {
    const [x, y, yaw] = pose, drv = S.state ? S.state.driver : "";
    g.fillStyle = COLOURS[whoDrives(drv)];
    g.strokeStyle = "#222"; g.lineWidth = 1.5 * px;
    g.beginPath(); g.arc(x, y, 0.25, 0, 2 * Math.PI); g.fill(); g.stroke();
    g.beginPath(); g.moveTo(x, y); g.lineTo(x + 0.3 * Math.cos(yaw), y + 0.3 * Math.sin(yaw)); g.stroke();
    g.fillStyle = "#222"; g.beginPath(); g.arc(x + 0.3 * Math.cos(yaw), y + 0.3 * Math.sin(yaw), 3 * px, 0, 2 * Math.PI); g.fill();
    const el = $("pose");
    el.dataset.x = x.toFixed(3); el.dataset.y = y.toFixed(3); el.dataset.yaw = yaw.toFixed(3);
    el.dataset.scan = sc ? sc.id : "";
    el.textContent = `${x.toFixed(2)}, ${y.toFixed(2)}, ${(yaw * 180 / Math.PI).toFixed(0)}\u00b0`;
  }
  marks(px); // above the robot: a robot looping in place sits on its own mark
  g.setTransform(dpr, 0, 0, dpr, 0, 0);
  scaleBar(h, v.scale);
  panel();
  S.shown = { pose, scan: sc };
}

// the world's beacons, discs of their colour with their id; those the robot's fiducial finder
// sees now ringed, a dashed line from the robot to each (an unidentified one, id 0, where the
// finder says it is)
function beacons(px, pose) {
  const list = S.world ? S.world.beacons || [] : [];
  const items = S.fiducial ? S.fiducial.items : [];
  const seen = new Set(items.map((i) => i.id));
  for (const b of list) {
    const [x, y] = b.pos, r = Math.max(b.size / 2, 3 * px);
    g.fillStyle = b.colour; g.strokeStyle = "#222"; g.lineWidth = px;
    g.beginPath(); g.arc(x, y, r, 0, 2 * Math.PI); g.fill(); g.stroke();
    if (seen.has(b.id)) {
      g.strokeStyle = "rgba(255,190,0,0.95)"; g.lineWidth = 3 * px;
      g.beginPath(); g.arc(x, y, r + 5 * px, 0, 2 * Math.PI); g.stroke();
    }
    g.save(); g.translate(x, y); g.scale(px, -px);
    g.fillStyle = "#222"; g.font = "bold 11px system-ui, sans-serif";
    g.fillText(String(b.id), r / px + 4, -r / px - 2);
    g.restore();
  }
  if (pose && items.length) {
    const [x, y, yaw] = pose;
    g.setLineDash([5 * px, 4 * px]); g.strokeStyle = "rgba(230,160,0,0.9)"; g.lineWidth = 1.5 * px;
    g.beginPath();
    for (const i of items) {
      g.moveTo(x, y);
      g.lineTo(x + i.range * Math.cos(yaw + i.bearing), y + i.range * Math.sin(yaw + i.bearing));
    }
    g.stroke(); g.setLineDash([]);
  }
  const ids = list.map((b) => b.id).join(","), shown = [...seen].sort((a, b) => a - b).join(",");
  if (canvas.dataset.beacons !== ids) canvas.dataset.beacons = ids;
  if (canvas.dataset.seen !== shown) canvas.dataset.seen = shown;
}

// a light grid every metre (every 5 m when zoomed out), in world coordinates
function grid(w, h, px) {
  const step = S.view.scale < 12 ? 5 : 1;
  const [x0, y1] = toWorld(0, 0), [x1, y0] = toWorld(w, h);
  g.strokeStyle = "rgba(0,0,0,0.06)"; g.lineWidth = px; g.beginPath();
  for (let x = Math.ceil(x0 / step) * step; x <= x1; x += step) { g.moveTo(x, y0); g.lineTo(x, y1); }
  for (let y = Math.ceil(y0 / step) * step; y <= y1; y += step) { g.moveTo(x0, y); g.lineTo(x1, y); }
  g.stroke();
}

// a bar of a round length at the bottom left, in screen pixels
function scaleBar(h, scale) {
  const nice = [0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50];
  const metres = nice.find((m) => m * scale >= 60) || 50, len = metres * scale;
  g.strokeStyle = "#222"; g.lineWidth = 2; g.beginPath();
  g.moveTo(12, h - 14); g.lineTo(12 + len, h - 14);
  g.moveTo(12, h - 19); g.lineTo(12, h - 9); g.moveTo(12 + len, h - 19); g.lineTo(12 + len, h - 9);
  g.stroke();
  g.fillStyle = "#222"; g.font = "12px system-ui, sans-serif";
  g.fillText(`${metres} m`, 16 + len, h - 10);
  canvas.dataset.scaleBar = String(metres);
}

function startsDrawn(px) {
  (S.world.starts || []).forEach(([x, y, yaw], i) => {
    g.save(); g.translate(x, y); g.rotate(yaw);
    g.strokeStyle = "rgba(40,120,40,0.8)"; g.lineWidth = 1.5 * px; g.beginPath();
    g.moveTo(0.2, 0); g.lineTo(-0.12, 0.12); g.lineTo(-0.12, -0.12); g.closePath(); g.stroke();
    g.restore();
    g.save(); g.translate(x, y); g.scale(px, -px);
    g.fillStyle = "rgba(40,120,40,0.9)"; g.font = "11px system-ui, sans-serif";
    g.fillText(String(i + 1), 10, -8);
    g.restore();
  });
}

// the trail, each piece in the colour of who drove it (null: a jump)
function trail(px) {
  const t = S.trail;
  g.lineWidth = 2 * px; g.lineCap = "round"; g.globalAlpha = 0.75;
  let colour = null; // one path per run of the same driver
  for (let i = 1; i < t.length; i++) {
    const a = t[i - 1], b = t[i];
    if (!a || !b) continue;
    if (COLOURS[b[2]] !== colour) {
      if (colour) g.stroke();
      colour = COLOURS[b[2]]; g.strokeStyle = colour; g.beginPath();
    }
    g.moveTo(a[0], a[1]); g.lineTo(b[0], b[1]);
  }
  if (colour) g.stroke();
  g.globalAlpha = 1;
}

// where the learned robot looped (purple ring), stalled (teal square), collided (crimson X);
// where the tree asks to be shown (an orange ring, its heading and "?n"); where it is stuck now,
// a pulsing ring
const ASK_COLOUR = "#d2691e";
function marks(px) {
  const m = S.teach;
  if (!m) return;
  for (const k of m.markers) {
    g.strokeStyle = MARKS[k.kind] || "#000"; g.fillStyle = g.strokeStyle; g.lineWidth = 2.5 * px;
    const r = 0.18;
    g.beginPath();
    if (k.kind === "loop") g.arc(k.x, k.y, r, 0, 2 * Math.PI);
    else if (k.kind === "stall") g.rect(k.x - r, k.y - r, 2 * r, 2 * r);
    else { g.moveTo(k.x - r, k.y - r); g.lineTo(k.x + r, k.y + r); g.moveTo(k.x - r, k.y + r); g.lineTo(k.x + r, k.y - r); }
    g.stroke();
    if (k.count > 1) {
      g.save(); g.translate(k.x, k.y); g.scale(px, -px);
      g.font = "bold 11px system-ui, sans-serif"; g.fillText(`\u00d7${k.count}`, 10, 14); g.restore();
    }
  }
  for (const a of m.asks || []) {  // the places the robot asks to be shown: a "?" and its heading
    const [x, y, yaw] = a.pose;
    g.strokeStyle = ASK_COLOUR; g.fillStyle = ASK_COLOUR; g.lineWidth = 2 * px;
    g.beginPath(); g.arc(x, y, 0.2, 0, 2 * Math.PI);
    g.moveTo(x, y); g.lineTo(x + 0.3 * Math.cos(yaw), y + 0.3 * Math.sin(yaw)); g.stroke();
    g.save(); g.translate(x, y); g.scale(px, -px);
    g.font = "bold 13px system-ui, sans-serif"; g.fillText(`?${a.n}`, 12, -8); g.restore();
  }
  if (m.stuck && Number.isFinite(m.stuck.x)) {
    const r = 0.35 + 0.1 * Math.sin(performance.now() / 200);
    g.strokeStyle = MARKS.loop; g.lineWidth = 3 * px;
    g.beginPath(); g.arc(m.stuck.x, m.stuck.y, r, 0, 2 * Math.PI); g.stroke();
  }
}

function panel() {
  const st = S.state, drv = st ? st.driver : "";
  $("driver").textContent = st ? (drv || "nobody") : "-";
  $("driver").dataset.driver = drv;
  const c = drv ? S.cmds[drv.split(/[-:.]/)[0]] || S.cmds[drv] : null;
  $("action").textContent = !st ? "-" : !drv ? "stopped" : c ? c.action : "?";
  $("action").dataset.action = st && drv && c ? c.action : "";
  if (st) {
    const ck = $("clock");
    if (ck.dataset.t !== st.ts.toFixed(2)) {
      ck.dataset.t = st.ts.toFixed(2);
      const m = Math.floor(st.ts / 60), sec = st.ts - 60 * m;
      ck.textContent = `${m}:${sec.toFixed(1).padStart(4, "0")} (${st.ts.toFixed(1)} s)`;
    }
  }
  const n = S.notice;
  if (n) {
    const t = $("tree");
    t.dataset.nodes = n.nodes; t.dataset.vectors = n.vectors;
    t.textContent = `${n.nodes} nodes, height ${n.height}, ${n.vectors} vectors`;
  }
  const d = S.decision;
  if (d && d !== panel.shown) {
    panel.shown = d;
    const win = d.path[d.path.length - 1];
    const guard = d.executed ? ` (the guard commanded ${d.executed})` : "";
    $("decision").dataset.looping = d.looping ? "1" : "0";
    $("decision").textContent = win
      ? `${d.action}${guard}: sphere #${win.index}, radius ${win.radius === null ? "inf" : win.radius.toFixed(3)}, depth ${win.depth} (scan ${d.scan_id}, tree ${d.snapshot_id || "from a file"}, ${d.nodes} nodes)`
      : d.action;
    // a tree with goals: the goal pursued, and why the last one changed (docs/goals.md)
    const g = d.goal, p = $("pursued");
    p.dataset.index = g ? g.index : ""; p.dataset.beacon = g ? g.beacon : "";
    p.title = d.goal_why || "";
    p.textContent = g ? `goal ${g.index + 1}/${g.count} (beacon ${g.beacon})${d.goal_why ? "; last change: " + d.goal_why : ""}` : "-";
    $("path").innerHTML = "";
    for (const e of d.path) {
      const li = document.createElement("li");
      li.textContent = `#${e.index} ${e.label} r=${e.radius === null ? "inf" : e.radius.toFixed(3)}`;
      $("path").appendChild(li);
    }
  }
}

function frame(now) {
  pollGamepad();
  const t = performance.now();
  draw();
  S.drawMs = (S.drawMs || 0) + performance.now() - t;
  S.frames++; S.fpsN++;
  if (now - S.fpsT0 >= 1000) {
    const fps = (1000 * S.fpsN) / (now - S.fpsT0), ms = S.drawMs / S.fpsN;
    $("fps").dataset.fps = fps.toFixed(1);
    $("fps").dataset.drawMs = ms.toFixed(2);
    $("fps").textContent = `${fps.toFixed(0)} frames/s, ${ms.toFixed(1)} ms to draw`;
    S.fpsT0 = now; S.fpsN = 0; S.drawMs = 0;
  }
  $("fps").dataset.frames = S.frames;
  requestAnimationFrame(frame);
}

// while a key is held, say so at least every 200 ms even when scans come slowly (the console
// stops the person's commands after 0.5 s without a word from the page)
setInterval(() => { if (S.sent && S.scan) send({ t: "drive", action: S.sent, scan_id: S.scan.id }); }, 200);

// What the page shows now, for a person model driving the page (benchmarks/bench_teach.py) or a
// test: read-only, a fresh copy each call; the keys are pressed on the page like a person's.
Object.defineProperty(window, "rhbl", { value: Object.freeze({
  view() {
    const st = S.state, sh = S.shown || {}, drv = st ? st.driver : "";
    const c = drv ? S.cmds[drv.split(/[-:.]/)[0]] || S.cmds[drv] : null;
    return {
      t: st ? st.ts : null, pose: sh.pose ? sh.pose.slice() : null,
      walls: S.world ? S.world.walls.map((w) => w.slice()) : [], starts: S.world ? (S.world.starts || []).map((p) => p.slice()) : [],
      beacons: S.world ? (S.world.beacons || []).map((b) => ({ id: b.id, pos: b.pos.slice(), colour: b.colour })) : [],
      seen: S.fiducial ? S.fiducial.items.map((i) => ({ ...i })) : [],
      mode: S.mode, driver: drv, action: drv && c ? c.action : null,
      scan_id: sh.scan ? sh.scan.id : null, holder: $("hold").dataset.holder || "",
      stuck: S.teach && S.teach.stuck ? S.teach.stuck.why : null, link: $("link").dataset.state || "",
      markers: S.teach ? S.teach.markers.map((k) => ({ ...k })) : [],
      goal: S.world && S.world.goal ? S.world.goal.slice() : null,
      pursued: S.decision && S.decision.goal ? { ...S.decision.goal, why: S.decision.goal_why } : null,
      yours: S.teach && S.teach.goals ? { ...S.teach.goals } : null,
    };
  },
}) });

connect();
requestAnimationFrame(frame);
