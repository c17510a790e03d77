// iwsim viewer page: decodes the viewer's frames (see viewer/src/frame.rs) and draws the
// world top-down. Wheel zooms, drag pans, a click on a chair follows it.
"use strict";

const HEADER_BYTES = 28, ROBOT_BYTES = 36;

// Decodes one binary frame; null when it is not one. Kept free of the DOM so tests can run it.
function decodeFrame(buf) {
  const v = new DataView(buf);
  if (buf.byteLength < HEADER_BYTES) return null;
  if (String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3)) !== "IWVF") return null;
  if (v.getUint16(4, true) !== 1) return null;
  const n = v.getUint32(24, true);
  if (buf.byteLength !== HEADER_BYTES + n * ROBOT_BYTES) return null;
  const robots = [];
  for (let k = 0; k < n; k++) {
    const o = HEADER_BYTES + k * ROBOT_BYTES;
    robots.push({
      id: v.getUint32(o, true), kind: v.getUint8(o + 4), flags: v.getUint8(o + 5),
      x: v.getFloat32(o + 8, true), y: v.getFloat32(o + 12, true), heading: v.getFloat32(o + 16, true),
      width: v.getFloat32(o + 20, true), height: v.getFloat32(o + 24, true), com: v.getFloat32(o + 28, true),
      collisions: v.getUint32(o + 32, true),
    });
  }
  return { runState: v.getUint8(6), tick: Number(v.getBigUint64(8, true)), simTime: v.getFloat64(16, true), robots };
}

// Body corners in the world, counter-clockwise from front-right (thesis Table 4.1).
function corners(r) {
  const a = r.heading * Math.PI / 180, c = Math.cos(a), s = Math.sin(a);
  const f = r.com * r.width, b = -(1 - r.com) * r.width, h = r.height / 2;
  return [[f, -h], [f, h], [b, h], [b, -h]].map(([x, y]) => [r.x + c * x - s * y, r.y + s * x + c * y]);
}

if (typeof module !== "undefined") module.exports = { decodeFrame, corners };

if (typeof document !== "undefined") {
  const canvas = document.getElementById("view"), ctx = canvas.getContext("2d"), hud = document.getElementById("hud");
  let map = null, frame = null, names = new Map(), follow = null, fps = 0, frames = 0, fpsAt = performance.now();
  let view = { scale: 20, ox: 0, oy: 0, fitted: false };
  const STATES = ["waiting", "running", "paused", "finished"];

  function fit() {
    if (!map) return;
    const w = canvas.width, h = canvas.height;
    view.scale = Math.min(w / (map.width + 2), h / (map.height + 2));
    view.ox = (w - map.width * view.scale) / 2;
    view.oy = (h + map.height * view.scale) / 2;
    view.fitted = true;
  }
  function toScreen([x, y]) { return [view.ox + x * view.scale, view.oy - y * view.scale]; }
  function poly(pts) { ctx.beginPath(); pts.map(toScreen).forEach(([x, y], i) => i ? ctx.lineTo(x, y) : ctx.moveTo(x, y)); ctx.closePath(); }

  function draw() {
    canvas.width = canvas.clientWidth; canvas.height = canvas.clientHeight;
    if (map && !view.fitted) fit();
    if (follow !== null && frame) {
      const r = frame.robots.find(r => r.id === follow);
      if (r) { view.ox = canvas.width / 2 - r.x * view.scale; view.oy = canvas.height / 2 + r.y * view.scale; }
    }
    ctx.fillStyle = "#f4f4f0"; ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (map) {
      ctx.fillStyle = "#ffffff"; poly([[0, 0], [map.width, 0], [map.width, map.height], [0, map.height]]); ctx.fill();
      ctx.strokeStyle = "#e4e4e4"; ctx.lineWidth = 1;
      for (let x = 0; x <= map.width; x++) { ctx.beginPath(); ctx.moveTo(...toScreen([x, 0])); ctx.lineTo(...toScreen([x, map.height])); ctx.stroke(); }
      for (let y = 0; y <= map.height; y++) { ctx.beginPath(); ctx.moveTo(...toScreen([0, y])); ctx.lineTo(...toScreen([map.width, y])); ctx.stroke(); }
      ctx.fillStyle = "#20407a";
      for (const w of map.walls) { poly(w.corners); ctx.fill(); }
      ctx.strokeStyle = "#202020"; ctx.lineWidth = 2; poly([[0, 0], [map.width, 0], [map.width, map.height], [0, map.height]]); ctx.stroke();
      ctx.fillStyle = "rgba(40,160,60,0.25)";
      for (const [x, y, r] of map.targets) { const [sx, sy] = toScreen([x, y]); ctx.beginPath(); ctx.arc(sx, sy, r * view.scale, 0, 2 * Math.PI); ctx.fill(); }
      ctx.fillStyle = "#e0a000";
      for (const [x, y] of map.beacons) { const [sx, sy] = toScreen([x, y]); ctx.beginPath(); ctx.arc(sx, sy, 5, 0, 2 * Math.PI); ctx.fill(); }
    }
    if (frame) {
      for (const r of frame.robots) {
        const colliding = (r.flags & 1) !== 0;
        ctx.fillStyle = colliding ? "#e02020" : (r.kind === 2 ? "#8a5a2b" : "#20a040");
        poly(corners(r)); ctx.fill();
        ctx.strokeStyle = "#000"; ctx.lineWidth = 1; ctx.stroke();
        const [sx, sy] = toScreen([r.x, r.y]);
        ctx.fillStyle = "#000"; ctx.fillText(names.get(r.id) || ("#" + r.id), sx + 6, sy - 6);
      }
      const collisions = frame.robots.reduce((a, r) => a + r.collisions, 0);
      hud.textContent = `${map ? map.name : ""}  tick ${frame.tick}  t ${frame.simTime.toFixed(1)} s  ${STATES[frame.runState] || ""}  ` +
        `${frame.robots.length} robots  ${collisions} contacts  ${fps} fps`;
    }
    requestAnimationFrame(draw);
  }

  function connect() {
    const ws = new WebSocket(`ws://${location.host}/ws`);
    ws.binaryType = "arraybuffer";
    window.iwsimSocket = ws;
    ws.onmessage = (e) => {
      if (typeof e.data === "string") {
        const m = JSON.parse(e.data);
        if (m.type === "map") { map = m; view.fitted = false; }
        else if (m.type === "roster") names = new Map(m.names);
        else if (m.type === "error") hud.textContent = m.message;
        return;
      }
      const f = decodeFrame(e.data);
      if (f) { frame = f; frames++; window.iwsimFrame = f; }
      const now = performance.now();
      if (now - fpsAt > 1000) { fps = frames; frames = 0; fpsAt = now; }
    };
    ws.onclose = () => setTimeout(connect, 1000);
  }

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
    if (Math.abs(e.offsetX - drag[0]) + Math.abs(e.offsetY - drag[1]) > 3) { drag[4] = true; follow = null; }
  });
  canvas.addEventListener("mouseup", (e) => {
    if (drag && !drag[4] && frame) {
      const x = (e.offsetX - view.ox) / view.scale, y = (view.oy - e.offsetY) / view.scale;
      const hit = frame.robots.find(r => Math.hypot(r.x - x, r.y - y) < Math.max(r.width, r.height));
      follow = hit ? hit.id : null;
    }
    drag = null;
  });
  for (const b of document.querySelectorAll("button[data-cmd]")) {
    b.addEventListener("click", () => window.iwsimSocket && window.iwsimSocket.send(b.dataset.cmd));
  }
  connect();
  requestAnimationFrame(draw);
}
