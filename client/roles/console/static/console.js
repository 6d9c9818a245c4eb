// rhbl console: draws what the console process forwards from the bus and sends the person's
// commands back. Plain JS, no framework, no network beyond the page's own WebSocket.
// Messages: client/roles/console/app.py (docstring). Exposed for tests and people: #pose data-x/y/yaw
// (the pose drawn last), #hold data-holder, #tree data-nodes/vectors, #fps data-fps/frames.
"use strict";

const $ = (id) => document.getElementById(id);
const canvas = $("view");
const g = canvas.getContext("2d");

const S = {
  ws: null, page: null, robot: null, viewOnly: false, mode: "demonstrate",
  world: null, state: null, scan: null, notice: null, decision: null, control: null,
  cmds: {}, trail: [],
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
  ws.onclose = () => {
    setLink(false);
    S.keys.clear(); S.pad = null; S.sent = null; // nothing is sent on a dead link anyway
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
      if (m.view_only) {
        for (const el of document.querySelectorAll("#pad button, #modes input, #take")) el.disabled = true;
        $("hold").textContent = "view-only console: watching";
      }
      break;
    }
    case "robots": setRobots(m.robots); break;
    case "world": S.world = m; S.view.fitted = false; canvas.dataset.walls = m.walls.length; break;
    case "state":
      S.state = m;
      { // a jump (a teleport) starts a new trail
        const last = S.trail[S.trail.length - 1];
        if (last && Math.hypot(m.pose[0] - last[0], m.pose[1] - last[1]) > 1.0) S.trail = [];
      }
      S.trail.push([m.pose[0], m.pose[1]]);
      if (S.trail.length > 2000) S.trail.splice(0, S.trail.length - 2000);
      break;
    case "scan":
      S.scan = m;
      if (S.sent) { send({ t: "drive", action: S.sent, scan_id: m.id }); S.sentScan = m.id; }
      break;
    case "notice": S.notice = m; break;
    case "decision": S.decision = m; break;
    case "cmd": S.cmds[m.source] = m; break;
    case "control": S.control = m; showHold(); break;
    case "error": showError(m.error); break;
  }
}

function setRobots(names) {
  const sel = $("robot");
  const have = Array.from(sel.options).map((o) => o.value).join();
  if (have === names.join()) return;
  sel.innerHTML = "";
  for (const n of names) sel.add(new Option(n, n, false, n === S.robot));
}

$("robot").onchange = (e) => {
  release();
  S.robot = e.target.value; S.world = null; S.state = null; S.scan = null; S.notice = null;
  S.decision = null; S.control = null; S.cmds = {}; S.trail = [];
  send({ t: "view", robot: S.robot });
};

for (const r of document.querySelectorAll("#modes input")) {
  r.onchange = () => { S.mode = r.value; release(); send({ t: "mode", mode: S.mode }); };
}
$("take").onclick = () => send({ t: "take" });
$("follow").onchange = (e) => { S.follow = e.target.checked; };

function showHold() {
  const c = S.control, el = $("hold");
  if (S.viewOnly) return;
  let who = "none";
  if (c && c.holder !== null) who = c.holder === S.page ? "me" : "other";
  el.dataset.holder = who;
  el.textContent = who === "me" ? `you hold the robot (${c.holder_mode})`
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

addEventListener("keydown", (e) => {
  if (e.target.tagName === "SELECT") return;
  if (e.key === " " || e.key === "Escape") { e.preventDefault(); release(); return; }
  const k = KEYS[e.key];
  if (!k) return;
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
let drag = null;
canvas.addEventListener("pointerdown", (e) => { canvas.focus(); drag = [e.offsetX, e.offsetY]; });
canvas.addEventListener("pointermove", (e) => {
  if (!drag) return;
  const dx = e.offsetX - drag[0], dy = e.offsetY - drag[1];
  if (Math.abs(dx) + Math.abs(dy) < 3) return;
  S.view.cx -= dx / S.view.scale; S.view.cy += dy / S.view.scale; drag = [e.offsetX, e.offsetY];
  if (S.follow) { S.follow = false; $("follow").checked = false; }
});
addEventListener("pointerup", () => { drag = null; });

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
  if (S.world) {
    if (S.world.goal) {
      const [gx, gy, gr] = S.world.goal;
      g.fillStyle = "rgba(40,170,60,0.25)"; g.beginPath(); g.arc(gx, gy, gr, 0, 2 * Math.PI); g.fill();
    }
    g.strokeStyle = "#333"; g.lineWidth = 0.04; g.lineCap = "round"; g.beginPath();
    for (const [a, b, c, d] of S.world.walls) { g.moveTo(a, b); g.lineTo(c, d); }
    g.stroke();
  }
  if (S.trail.length > 1) {
    g.strokeStyle = "rgba(74,144,217,0.7)"; g.lineWidth = 2 * px; g.beginPath();
    g.moveTo(S.trail[0][0], S.trail[0][1]);
    for (const [x, y] of S.trail) g.lineTo(x, y);
    g.stroke();
  }
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
  if (pose) {
    const [x, y, yaw] = pose, drv = S.state ? S.state.driver : "";
    g.fillStyle = drv.startsWith("teacher") ? "#e8a33d" : drv.startsWith("controller") ? "#4a90d9" : "#999";
    g.strokeStyle = "#222"; g.lineWidth = 1.5 * px;
    g.beginPath(); g.arc(x, y, 0.25, 0, 2 * Math.PI); g.fill(); g.stroke();
    g.beginPath(); g.moveTo(x, y); g.lineTo(x + 0.3 * Math.cos(yaw), y + 0.3 * Math.sin(yaw)); g.stroke();
    const el = $("pose");
    el.dataset.x = x.toFixed(3); el.dataset.y = y.toFixed(3); el.dataset.yaw = yaw.toFixed(3);
    el.dataset.scan = sc ? sc.id : "";
    el.textContent = `${x.toFixed(2)}, ${y.toFixed(2)}, ${(yaw * 180 / Math.PI).toFixed(0)}\u00b0`;
  }
  panel();
}

function panel() {
  const st = S.state, drv = st ? st.driver : "";
  $("driver").textContent = st ? (drv || "nobody") : "-";
  $("driver").dataset.driver = drv;
  const c = drv ? S.cmds[drv.split(/[-:.]/)[0]] || S.cmds[drv] : null;
  $("action").textContent = !st ? "-" : !drv ? "stopped" : c ? c.action : "?";
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
    $("decision").textContent = win
      ? `${d.action}: sphere #${win.index}, radius ${win.radius === null ? "inf" : win.radius.toFixed(3)}, depth ${win.depth} (scan ${d.scan_id}, tree ${d.snapshot_id || "from a file"}, ${d.nodes} nodes)`
      : d.action;
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

connect();
requestAnimationFrame(frame);
