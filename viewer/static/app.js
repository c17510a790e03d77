// iwsim viewer page: decodes the viewer's frames (see viewer/src/frame.rs), draws the world
// top-down on a canvas, and hands the same data to the 3D view (view3d.js, loaded only when
// the 3D view is first shown, so a browser without WebGL still gets the 2D view).
//
// 2D: wheel zooms, drag pans, a click on a chair follows it. The URL can preset the page:
// ?view=3d&camera=first|third|free&chair=ID|NAME&grid=0&labels=0&cones=0; in 2D, chair= also
// follows that chair and zoom=K magnifies the fitted view K times.
//
// Mixed reality: a physical chair's frame entry brings its real and virtual readings, drawn
// as two sets of cones in two colours, and the true pose a test bench reports (the chair
// emulator's), drawn as a dashed "ghost" of the body joined to the odometry pose, with the
// drift in the chair's label and in the chairs panel beside the sensor mode.
"use strict";

const HEADER_BYTES = 28, ROBOT_BYTES = 52, CHAIR_BYTES = 52, MAX_PROXIMITY = 8, NO_READING = 0xffff, VERSION = 3;
// `ipc_types::SensorMode` by value, and the `ipc_types::CHAIR_*` bits.
const SENSOR_MODES = ["virtual", "real", "augmented"];
const CHAIR_CONTROLLED = 1, CHAIR_LINK_UP = 2, CHAIR_GHOST = 4;

// Eight u16 millimetre readings at byte `o`, as metres or null (none, no echo, no sensor).
function readingsAt(v, o) {
  const out = [];
  for (let s = 0; s < MAX_PROXIMITY; s++) {
    const mm = v.getUint16(o + 2 * s, true);
    out.push(mm === NO_READING ? null : mm / 1000);
  }
  return out;
}

// Decodes one binary frame; null when it is not one. Kept free of the DOM so tests can run it.
function decodeFrame(buf) {
  const v = new DataView(buf);
  if (buf.byteLength < HEADER_BYTES) return null;
  if (String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3)) !== "IWVF") return null;
  if (v.getUint16(4, true) !== VERSION) return null;
  const n = v.getUint32(24, true), chairsAt = HEADER_BYTES + n * ROBOT_BYTES;
  if (buf.byteLength < chairsAt + 4) return null;
  const nc = v.getUint32(chairsAt, true);
  if (buf.byteLength !== chairsAt + 4 + nc * CHAIR_BYTES) return null;
  const robots = new Array(n);
  for (let k = 0; k < n; k++) {
    const o = HEADER_BYTES + k * ROBOT_BYTES;
    const proximity = readingsAt(v, o + 36);
    robots[k] = {
      id: v.getUint32(o, true), kind: v.getUint8(o + 4), flags: v.getUint8(o + 5),
      x: v.getFloat32(o + 8, true), y: v.getFloat32(o + 12, true), heading: v.getFloat32(o + 16, true),
      width: v.getFloat32(o + 20, true), height: v.getFloat32(o + 24, true), com: v.getFloat32(o + 28, true),
      collisions: v.getUint32(o + 32, true), proximity,
    };
  }
  const chairs = new Array(nc);
  for (let k = 0; k < nc; k++) {
    const o = chairsAt + 4 + k * CHAIR_BYTES, flags = v.getUint8(o + 5), mode = v.getUint8(o + 4);
    chairs[k] = {
      id: v.getUint32(o, true), mode: SENSOR_MODES[mode] || `mode ${mode}`, flags,
      ghost: flags & CHAIR_GHOST ? [v.getFloat32(o + 8, true), v.getFloat32(o + 12, true), v.getFloat32(o + 16, true)] : null,
      real: readingsAt(v, o + 20), virtual: readingsAt(v, o + 36),
    };
  }
  return { runState: v.getUint8(6), tick: Number(v.getBigUint64(8, true)), simTime: v.getFloat64(16, true), robots, chairs };
}

// A chair's odometry drift: metres from the pose it reports (its robot entry) to the true
// pose of its ghost; null without a ghost.
function drift(r, c) {
  return c && c.ghost ? Math.hypot(c.ghost[0] - r.x, c.ghost[1] - r.y) : null;
}

// The robot `r` moved to its chair's ghost pose, for drawing the ghost with the same body.
function ghostOf(r, c) {
  return { ...r, x: c.ghost[0], y: c.ghost[1], heading: c.ghost[2] };
}

// A body-frame point (along, across the heading from the centre of movement) in the lab frame.
function toLab(r, x, y) {
  const a = r.heading * Math.PI / 180, c = Math.cos(a), s = Math.sin(a);
  return [r.x + c * x - s * y, r.y + s * x + c * y];
}

// `RobotState::flags` bit ROBOT_DISC: the body is a disc of diameter `width` centred on (x, y)
// (a plain Ciber-Rato robot); otherwise a width × height rectangle placed by `com`.
const ROBOT_DISC = 8;
function isDisc(r) { return (r.flags & ROBOT_DISC) !== 0; }

// Body corners in the lab frame, counter-clockwise from front-right (thesis Table 4.1).
function corners(r) {
  const f = r.com * r.width, b = -(1 - r.com) * r.width, h = r.height / 2;
  return [[f, -h], [f, h], [b, h], [b, -h]].map(([x, y]) => toLab(r, x, y));
}

// A proximity cone in the lab frame: apex at the sensor, radius = the reading capped at the
// sensor's range, and the arc's start and end angles (radians, counter-clockwise from +x).
// `sensor` = [x, y, angle, cone, range] in the body frame, metres and degrees.
function coneArc(r, sensor, reading) {
  const [sx, sy, angle, cone, range] = sensor;
  const mid = (r.heading + angle) * Math.PI / 180, half = cone * Math.PI / 360;
  return { apex: toLab(r, sx, sy), radius: Math.min(reading, range), a0: mid - half, a1: mid + half };
}

if (typeof module !== "undefined") module.exports = { decodeFrame, corners, coneArc, isDisc, drift, ghostOf };

if (typeof document !== "undefined") {
  const params = new URLSearchParams(location.search);
  const flag = (name, dflt) => (params.has(name) ? params.get(name) !== "0" : dflt);
  const $ = (id) => document.getElementById(id);
  const canvas = $("view2d"), ctx = canvas.getContext("2d"), canvas3d = $("view3d"), hud = $("hud"), status = $("status");
  const STATES = ["waiting", "running", "paused", "finished"];
  const CONES_MAX = 300, LABELS_MAX = 300;
  const zoom = Math.min(Math.max(Number(params.get("zoom")) || 1, 0.1), 50);
  const COLORS = {
    outside: "#f4f4f0", floor: "#ffffff", grid: "#e4e4e4", wall: "#20407a", obstacle: "#d07020",
    chair: "#20a040", real: "#2070d0", door: "#8a5a2b", collision: "#e02020",
    target: "rgba(40,160,60,0.25)", checkpoint: "rgba(200,0,200,0.35)", beacon: "#e0a000",
    cone: "rgba(255,150,0,0.22)", coneNear: "rgba(230,30,30,0.3)",
    // Mixed reality: a chair's real and virtual readings and its true pose (the ghost).
    realReading: "#ff6000", realCone: "rgba(255,96,0,0.16)",
    virtualReading: "#0040ff", virtualCone: "rgba(0,64,255,0.12)",
    ghost: "#d000d0", ghostFill: "rgba(208,0,208,0.25)",
  };
  const page = {
    map: null, frame: null, roster: new Map(), names: new Map(), chairs: new Map(),
    // ?chair= takes a robot id or a name; a name is resolved when the roster arrives.
    chair: /^\d+$/.test(params.get("chair") || "") ? Number(params.get("chair")) : null,
    chairName: params.has("chair") && !/^\d+$/.test(params.get("chair")) ? params.get("chair") : null,
    follow: /^\d+$/.test(params.get("chair") || "") ? Number(params.get("chair")) : null,
    mode: params.get("view") === "3d" ? "3d" : "2d", camera: params.get("camera") || "first",
    grid: flag("grid", true), labels: flag("labels", true), cones: flag("cones", true),
    view3d: null, view3dError: null, draws: 0, drawFps: 0, frames: 0, frameFps: 0, tickRate: 0,
    // Milliseconds of script spent drawing (and updating the 3D scene), summed, for benches.
    drawCostMs: 0,
  };
  window.iwsim = page;
  let view = { scale: 20, ox: 0, oy: 0, fitted: false };
  let ticks = [], drawsAt = performance.now(), drawsSeen = 0, framesSeen = 0;

  function fit() {
    const w = canvas.width, h = canvas.height;
    view.scale = Math.min(w / (page.map.width + 2), h / (page.map.height + 2)) * zoom;
    view.ox = (w - page.map.width * view.scale) / 2;
    view.oy = (h + page.map.height * view.scale) / 2;
    view.fitted = true;
  }
  const toScreen = ([x, y]) => [view.ox + x * view.scale, view.oy - y * view.scale];
  function poly(pts) {
    ctx.beginPath();
    pts.forEach((p, i) => { const [x, y] = toScreen(p); i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
    ctx.closePath();
  }
  function disc(x, y, radiusPx) { const [sx, sy] = toScreen([x, y]); ctx.beginPath(); ctx.arc(sx, sy, radiusPx, 0, 2 * Math.PI); }

  // A physical chair's cones: each sensor's virtual reading (the hub's, on the chair's twin)
  // and real reading (the chair's own) as a tinted wedge with a solid arc at the reading, each
  // only where it is a finite distance. The arcs make the two comparable when they overlap.
  function mixedCones(r, sensors, chair) {
    const k = view.scale;
    const sets = [[chair.virtual, COLORS.virtualCone, COLORS.virtualReading], [chair.real, COLORS.realCone, COLORS.realReading]];
    for (let i = 0; i < sensors.length; i++) {
      for (const [readings, fill, stroke] of sets) {
        const d = readings[i];
        if (d === null || d === undefined) continue;
        const c = coneArc(r, sensors[i], d), ax = view.ox + c.apex[0] * k, ay = view.oy - c.apex[1] * k;
        ctx.fillStyle = fill;
        ctx.beginPath(); ctx.moveTo(ax, ay); ctx.arc(ax, ay, c.radius * k, -c.a1, -c.a0); ctx.closePath(); ctx.fill();
        ctx.strokeStyle = stroke; ctx.lineWidth = 3;
        ctx.beginPath(); ctx.arc(ax, ay, c.radius * k, -c.a1, -c.a0); ctx.stroke();
      }
    }
    ctx.lineWidth = 1;
  }

  // Each chair's ghost: its body at the true pose, translucent with a dashed outline and a
  // heading line, and a thin line from the odometry pose's centre to the ghost's.
  function drawGhosts(f) {
    if (!f.chairs.length) return;
    ctx.save();
    ctx.strokeStyle = COLORS.ghost; ctx.fillStyle = COLORS.ghostFill;
    for (const c of f.chairs) {
      const r = c.ghost && f.robots.find((r) => r.id === c.id);
      if (!r) continue;
      const g = ghostOf(r, c);
      if (isDisc(g)) disc(g.x, g.y, g.width / 2 * view.scale); else poly(corners(g));
      ctx.fill();
      ctx.lineWidth = 2; ctx.setLineDash([6, 4]); ctx.stroke();
      ctx.setLineDash([]); ctx.lineWidth = 1;
      ctx.beginPath();
      ctx.moveTo(...toScreen([g.x, g.y])); ctx.lineTo(...toScreen(toLab(g, g.com * g.width, 0)));
      ctx.moveTo(...toScreen([r.x, r.y])); ctx.lineTo(...toScreen([g.x, g.y]));
      ctx.stroke();
    }
    ctx.restore();
  }

  // The chairs panel: the legend of the mixed-reality colours and, per chair, its sensor
  // mode, drift and link. Hidden while the run has no physical chair; rewritten only when its
  // text changes, not at every frame.
  let chairsHtml = null;
  function updateChairsPanel(f) {
    const panel = $("chairs");
    const rows = f.chairs.map((c) => {
      const r = f.robots.find((r) => r.id === c.id), d = r ? drift(r, c) : null;
      const name = page.names.get(c.id) || `#${c.id}`;
      const link = c.flags & CHAIR_LINK_UP ? "" : " · <b>link down</b>";
      const driven = c.flags & CHAIR_CONTROLLED ? "driven" : "not driven";
      return `<div class="chair">${escapeHtml(name)} · <b>${c.mode}</b> · ${d === null ? "no true pose" : `drift ${d.toFixed(2)} m`} · ${driven}${link}</div>`;
    });
    const html = rows.length ? `<div class="legend"><span class="swatch" style="background:${COLORS.realReading}"></span>real` +
      `<span class="swatch" style="background:${COLORS.virtualReading}"></span>virtual` +
      `<span class="swatch ghost" style="border-color:${COLORS.ghost}"></span>true pose</div>${rows.join("")}` : "";
    if (html === chairsHtml) return;
    chairsHtml = html;
    panel.innerHTML = html;
    panel.style.display = html ? "block" : "none";
  }
  function escapeHtml(t) { return t.replace(/[&<>"]/g, (ch) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[ch]); }

  function draw2d() {
    const m = page.map, f = page.frame, W = canvas.width, H = canvas.height;
    if (m && !view.fitted) fit();
    if (page.follow !== null && f) {
      const r = f.robots.find((r) => r.id === page.follow);
      if (r) { view.ox = W / 2 - r.x * view.scale; view.oy = H / 2 + r.y * view.scale; }
    }
    ctx.fillStyle = COLORS.outside; ctx.fillRect(0, 0, W, H);
    if (!m) return;
    const lab = [[0, 0], [m.width, 0], [m.width, m.height], [0, m.height]];
    ctx.fillStyle = COLORS.floor; poly(lab); ctx.fill();
    if (page.grid) {
      ctx.strokeStyle = COLORS.grid; ctx.lineWidth = 1; ctx.beginPath();
      for (let x = 0; x <= m.width; x++) { ctx.moveTo(...toScreen([x, 0])); ctx.lineTo(...toScreen([x, m.height])); }
      for (let y = 0; y <= m.height; y++) { ctx.moveTo(...toScreen([0, y])); ctx.lineTo(...toScreen([m.width, y])); }
      ctx.stroke();
    }
    ctx.fillStyle = COLORS.target;
    for (const [x, y, r] of m.targets) { disc(x, y, r * view.scale); ctx.fill(); }
    ctx.fillStyle = COLORS.checkpoint;
    m.checkpoints.forEach(([x, y, r], i) => {
      disc(x, y, r * view.scale); ctx.fill();
      const [sx, sy] = toScreen([x, y]); ctx.fillStyle = "#800080"; ctx.fillText(`checkpoint ${i + 1}`, sx + 4, sy + 14);
      ctx.fillStyle = COLORS.checkpoint;
    });
    for (const w of m.walls) { ctx.fillStyle = w.obstacle ? COLORS.obstacle : COLORS.wall; poly(w.corners); ctx.fill(); }
    ctx.strokeStyle = "#202020"; ctx.lineWidth = 2; poly(lab); ctx.stroke();
    ctx.fillStyle = COLORS.beacon;
    for (const [x, y] of m.beacons) { disc(x, y, 5); ctx.fill(); }
    if (!f) return;
    // Only what is on screen is drawn, and every colour goes in one path with one fill: with
    // a thousand chairs, per-chair fills and array allocations cost more than the drawing.
    const margin = 2 * view.scale, k = view.scale;
    const visible = f.robots.filter((r) => {
      const sx = view.ox + r.x * k, sy = view.oy - r.y * k;
      return sx > -margin && sx < W + margin && sy > -margin && sy < H + margin;
    });
    // Cones are filled one by one: Chromium's software rasteriser fills one path of
    // thousands of overlapping cones five times slower than the same cones apart. Past
    // CONES_MAX chairs on screen only the chosen chair's are drawn: they would be clutter.
    if (page.cones) {
      const chosenId = page.follow ?? page.chair;
      const withCones = visible.length <= CONES_MAX ? visible : visible.filter((r) => r.id === chosenId);
      for (const r of withCones) {
        const sensors = page.roster.get(r.id)?.sensors;
        if (!sensors) continue;
        const chair = page.chairs.get(r.id);
        if (chair) { mixedCones(r, sensors, chair); continue; }
        for (let i = 0; i < sensors.length; i++) {
          const d = r.proximity[i];
          if (d === null || d === undefined) continue;
          const c = coneArc(r, sensors[i], d);
          const ax = view.ox + c.apex[0] * k, ay = view.oy - c.apex[1] * k;
          ctx.fillStyle = d < 0.5 ? COLORS.coneNear : COLORS.cone;
          // Screen y points down, so world angles turn negative and the arc runs from -a1 to -a0.
          ctx.beginPath(); ctx.moveTo(ax, ay); ctx.arc(ax, ay, c.radius * k, -c.a1, -c.a0); ctx.closePath(); ctx.fill();
        }
      }
    }
    const bodies = { chair: new Path2D(), real: new Path2D(), door: new Path2D(), collision: new Path2D() };
    const heading = new Path2D();
    for (const r of visible) {
      const p = (r.flags & 1) ? bodies.collision : r.kind === 2 ? bodies.door : r.kind === 1 ? bodies.real : bodies.chair;
      if (isDisc(r)) {
        const cx = view.ox + r.x * k, cy = view.oy - r.y * k, R = r.width / 2 * k;
        p.moveTo(cx + R, cy); p.arc(cx, cy, R, 0, 2 * Math.PI);
      } else {
        const cs = corners(r);
        for (let i = 0; i < 4; i++) {
          const x = view.ox + cs[i][0] * k, y = view.oy - cs[i][1] * k;
          i ? p.lineTo(x, y) : p.moveTo(x, y);
        }
      }
      p.closePath();
      // A line from the centre of movement to the front shows the heading.
      const front = toLab(r, r.com * r.width, 0);
      heading.moveTo(view.ox + r.x * k, view.oy - r.y * k); heading.lineTo(view.ox + front[0] * k, view.oy - front[1] * k);
    }
    ctx.lineWidth = 1; ctx.strokeStyle = "#000";
    for (const [name, p] of Object.entries(bodies)) { ctx.fillStyle = COLORS[name]; ctx.fill(p); ctx.stroke(p); }
    ctx.stroke(heading);
    drawGhosts(f);
    const chosen = visible.find((r) => r.id === (page.follow ?? page.chair));
    if (chosen) {
      ctx.lineWidth = 3; ctx.strokeStyle = "#ffd000";
      if (isDisc(chosen)) {
        const [cx, cy] = toScreen([chosen.x, chosen.y]);
        ctx.beginPath(); ctx.arc(cx, cy, chosen.width / 2 * k, 0, 2 * Math.PI);
      } else poly(corners(chosen));
      ctx.stroke(); ctx.lineWidth = 1;
    }
    if (page.labels && visible.length <= LABELS_MAX) {
      ctx.fillStyle = "#000";
      for (const r of visible) {
        const [sx, sy] = toScreen([r.x, r.y]), name = page.names.get(r.id) || `#${r.id}`, c = page.chairs.get(r.id);
        const d = drift(r, c);
        ctx.fillText(c ? `${name} · ${c.mode}${d === null ? "" : ` · drift ${d.toFixed(2)} m`}` : name, sx + 8, sy - 8);
      }
    }
  }

  function drawHud() {
    const f = page.frame;
    if (!f) return;
    const contacts = f.robots.reduce((a, r) => a + r.collisions, 0), colliding = f.robots.filter((r) => r.flags & 1).length;
    hud.textContent = `${page.map ? page.map.name : ""} · tick ${f.tick} · t ${f.simTime.toFixed(1)} s · ${STATES[f.runState] || "?"} · ` +
      `${page.tickRate.toFixed(0)} ticks/s · ${f.robots.length} robots · ${contacts} contacts (${colliding} now) · ${page.drawFps} fps`;
  }

  async function ensure3d() {
    if (page.view3d || page.view3dError) return;
    try {
      const { createView3D } = await import("./view3d.js");
      page.view3d = createView3D(canvas3d);
      if (page.map) page.view3d.setMap(page.map);
      page.view3d.setShowGrid(page.grid); page.view3d.setShowLabels(page.labels);
      page.view3d.setCamera(page.camera, page.chair);
      if (page.frame) page.view3d.update(page.frame, page.names);
    } catch (e) {
      page.view3dError = String(e); status.textContent = `3D view unavailable: ${e}`;
    }
  }

  function setMode(mode) {
    page.mode = mode;
    canvas.style.display = mode === "2d" ? "block" : "none";
    canvas3d.style.display = mode === "3d" ? "block" : "none";
    $("camera").disabled = mode !== "3d";
    if (mode === "3d") ensure3d();
  }

  function frameLoop(now) {
    page.draws++;
    if (now - drawsAt >= 1000) {
      page.drawFps = Math.round(((page.draws - drawsSeen) * 1000) / (now - drawsAt));
      page.frameFps = Math.round(((page.frames - framesSeen) * 1000) / (now - drawsAt));
      drawsSeen = page.draws; framesSeen = page.frames; drawsAt = now;
    }
    const t0 = performance.now();
    if (page.mode === "2d") {
      if (canvas.width !== canvas.clientWidth || canvas.height !== canvas.clientHeight) {
        canvas.width = canvas.clientWidth; canvas.height = canvas.clientHeight; view.fitted = false;
      }
      draw2d();
    } else if (page.view3d) {
      page.view3d.render();
    }
    drawHud();
    page.drawCostMs += performance.now() - t0;
    requestAnimationFrame(frameLoop);
  }

  function fillChairs() {
    const sel = $("chair"), keep = page.chair;
    sel.replaceChildren(new Option("(first chair)", ""));
    for (const [id, e] of page.roster) sel.add(new Option(`${e.name || "#" + id} (${id})`, String(id)));
    sel.value = keep === null ? "" : String(keep);
  }

  function onMessage(e) {
    if (typeof e.data === "string") {
      const m = JSON.parse(e.data);
      if (m.type === "map") {
        page.map = m; view.fitted = false;
        if (page.view3d) page.view3d.setMap(m);
      } else if (m.type === "roster") {
        page.roster = new Map(m.robots.map((r) => [r.id, r]));
        page.names = new Map(m.robots.map((r) => [r.id, r.name]));
        const named = page.chairName && m.robots.find((r) => r.name === page.chairName);
        if (named) {
          page.chair = named.id; page.follow = named.id; page.chairName = null;
          if (page.view3d) page.view3d.setCamera(page.camera, page.chair);
        }
        fillChairs();
      } else if (m.type === "ack") {
        status.textContent = `${m.command}: done`;
      } else if (m.type === "error") {
        status.textContent = m.message;
      }
      return;
    }
    const f = decodeFrame(e.data);
    if (!f) return;
    page.frame = f; page.frames++;
    page.chairs = new Map(f.chairs.map((c) => [c.id, c]));
    updateChairsPanel(f);
    const now = performance.now();
    ticks.push([now, f.tick]);
    while (ticks.length > 2 && now - ticks[0][0] > 1000) ticks.shift();
    if (ticks.length > 1) {
      const [t0, k0] = ticks[0], [t1, k1] = ticks[ticks.length - 1];
      page.tickRate = t1 > t0 ? ((k1 - k0) * 1000) / (t1 - t0) : 0;
    }
    if (page.view3d) {
      const t0 = performance.now();
      page.view3d.update(f, page.names);
      page.drawCostMs += performance.now() - t0;
    }
  }

  function connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    ws.binaryType = "arraybuffer";
    page.socket = ws;
    ws.onmessage = onMessage;
    ws.onclose = () => { status.textContent = "disconnected: retrying"; setTimeout(connect, 1000); };
  }

  // 2D mouse: wheel zooms about the pointer, drag pans, a click selects and follows a chair.
  let drag = null;
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const k = e.deltaY < 0 ? 1.2 : 1 / 1.2;
    view.ox = e.offsetX - (e.offsetX - view.ox) * k; view.oy = e.offsetY - (e.offsetY - view.oy) * k; view.scale *= k;
  }, { passive: false });
  canvas.addEventListener("mousedown", (e) => { drag = [e.offsetX, e.offsetY, view.ox, view.oy, false]; });
  canvas.addEventListener("mousemove", (e) => {
    if (!drag) return;
    view.ox = drag[2] + e.offsetX - drag[0]; view.oy = drag[3] + e.offsetY - drag[1];
    if (Math.abs(e.offsetX - drag[0]) + Math.abs(e.offsetY - drag[1]) > 3) { drag[4] = true; page.follow = null; }
  });
  canvas.addEventListener("mouseup", (e) => {
    if (drag && !drag[4] && page.frame) {
      const x = (e.offsetX - view.ox) / view.scale, y = (view.oy - e.offsetY) / view.scale;
      const hit = page.frame.robots.find((r) => Math.hypot(r.x - x, r.y - y) < Math.max(r.width, r.height));
      page.follow = hit ? hit.id : null;
      if (hit) { page.chair = hit.id; $("chair").value = String(hit.id); if (page.view3d) page.view3d.setCamera(page.camera, hit.id); }
    }
    drag = null;
  });
  for (const b of document.querySelectorAll("button[data-cmd]")) {
    b.addEventListener("click", () => {
      if (!page.socket || page.socket.readyState !== 1) return;
      const cmd = b.dataset.cmd === "remove" ? `remove:${page.chair ?? ""}` : b.dataset.cmd;
      page.socket.send(cmd);
    });
  }
  for (const b of document.querySelectorAll("button[data-view]")) b.addEventListener("click", () => setMode(b.dataset.view));
  $("camera").value = page.camera;
  $("camera").addEventListener("change", (e) => { page.camera = e.target.value; if (page.view3d) page.view3d.setCamera(page.camera, page.chair); });
  $("chair").addEventListener("change", (e) => {
    page.chair = e.target.value === "" ? null : Number(e.target.value);
    page.follow = page.chair;
    if (page.view3d) page.view3d.setCamera(page.camera, page.chair);
  });
  for (const [id, key] of [["grid", "grid"], ["labels", "labels"], ["cones", "cones"]]) {
    $(id).checked = page[key];
    $(id).addEventListener("change", (e) => {
      page[key] = e.target.checked;
      if (page.view3d) { page.view3d.setShowGrid(page.grid); page.view3d.setShowLabels(page.labels); }
    });
  }
  setMode(page.mode);
  connect();
  requestAnimationFrame(frameLoop);
}
