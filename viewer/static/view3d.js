// iwsim 3D view. Draws the map and the robots of app.js's frames with three.js.
// Lab coordinates are used unchanged: x right, y up (north), z = height above the floor,
// metres; the camera's up vector is +z. Nearby robots are drawn with one InstancedMesh per
// part kind (boxes, wheels); far chairs are merged into a single mesh rebuilt on the CPU,
// because software WebGL (SwiftShader) charges ~13 us per instance but ~1 us per triangle.
import * as THREE from "./three.module.min.js";

const DEG = Math.PI / 180;
const CHAIR_COLOR = new THREE.Color(0x20a040), HIT_COLOR = new THREE.Color(0xe02020);
const DOOR_COLOR = new THREE.Color(0x8a5a2b), TYRE_COLOR = new THREE.Color(0x2a2a2a);
// A physical chair's true pose (a test bench's), drawn as a translucent block beside the
// odometry pose its robot shows, as the 2D view's ghost.
const GHOST_COLOR = new THREE.Color(0xd000d0);
const DOOR_HEIGHT = 2.0, CHAIR_TOP = 1.0, EYE_HEIGHT = 1.2;
// `ipc_types::ROBOT_DISC`: the robot is a disc of diameter `width` (a plain Ciber-Rato robot),
// drawn as a cylinder PUCK_HEIGHT tall.
const ROBOT_DISC = 8, PUCK_HEIGHT = 0.3;
const DETAILED_NEAREST = 16, DETAIL_RANGE = 25;   // chairs, metres
// Each label is its own sprite draw call (~0.2 ms each in software WebGL), hence the cap.
const LABEL_MAX = 30, LABEL_PX = 18;
const FOV = { first: 75, third: 60, free: 50 };

// Far-away chair: a unit block whose top slopes from the backrest (rear, x < 0) down to the
// seat front, so the heading still reads; the bottom face is dropped. 10 triangles, where the
// full model has about 140. BoxGeometry lists its faces +x,-x,+y,-y,+z,-z, 4 vertices each.
const FAR = (() => {
  const g = new THREE.BoxGeometry(1, 1, 1).translate(0, 0, 0.5), p = g.attributes.position;
  for (let i = 0; i < p.count; i++) if (p.getZ(i) > 0.5) p.setZ(i, p.getX(i) < 0 ? CHAIR_TOP : 0.55);
  g.computeVertexNormals();   // every face has its own vertices, so normals stay flat
  const far = { pos: p.array.slice(0, 60), nor: g.attributes.normal.array.slice(0, 60), index: g.index.array.slice(0, 30) };
  g.dispose();
  return far;
})();

export function createView3D(canvas) {
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0xdde6ee);
  const camera = new THREE.PerspectiveCamera(FOV.free, 1, 0.05, 2000);
  camera.up.set(0, 0, 1);

  // Hemisphere light for soft overall shade, plus a directional one from the south-west
  // so that the faces of a wall get visibly different brightness.
  const hemi = new THREE.HemisphereLight(0xffffff, 0x807868, 1.6);
  hemi.position.set(0, 0, 1);
  const sun = new THREE.DirectionalLight(0xffffff, 1.6);
  sun.position.set(-0.6, -1, 1.6);
  scene.add(hemi, sun);

  const mats = {
    floor: new THREE.MeshLambertMaterial({ color: 0xf4f4f0, polygonOffset: true, polygonOffsetFactor: 2, polygonOffsetUnits: 2 }),
    wall: new THREE.MeshLambertMaterial({ color: 0x20407a }),
    obstacle: new THREE.MeshLambertMaterial({ color: 0xe08020 }),
    edge: new THREE.LineBasicMaterial({ color: 0x0c1830 }),
    border: new THREE.MeshLambertMaterial({ color: 0x303030 }),
    grid: new THREE.LineBasicMaterial({ color: 0xb8b8b8 }),
    target: new THREE.MeshBasicMaterial({ color: 0x28a03c, transparent: true, opacity: 0.45, depthWrite: false }),
    checkpoint: new THREE.MeshBasicMaterial({ color: 0xd020d0, transparent: true, opacity: 0.45, depthWrite: false }),
    beacon: new THREE.MeshLambertMaterial({ color: 0xe0a000 }),
    body: new THREE.MeshLambertMaterial({ color: 0xffffff }),   // tinted per instance
    ghost: new THREE.MeshBasicMaterial({ color: 0xffffff, transparent: true, opacity: 0.35, depthWrite: false }),
  };
  const geos = {
    box: new THREE.BoxGeometry(1, 1, 1),
    wheel: new THREE.CylinderGeometry(1, 1, 1, 10),            // axis along local y = across the chair
    disc: new THREE.CircleGeometry(1, 40),
    puck: new THREE.CylinderGeometry(0.5, 0.5, 1, 32).rotateX(Math.PI / 2),   // unit cylinder, axis z
    pole: new THREE.CylinderGeometry(0.03, 0.03, 1, 8).rotateX(Math.PI / 2).translate(0, 0, 0.5),
    ball: new THREE.SphereGeometry(0.1, 12, 8),
  };

  let map = null, frame = null, names = new Map();
  let mode = "free", robotId = null, showGrid = true, showLabels = true;
  let usingFree = true, fitPending = true, width = 0, height = 0;
  const mapGroup = new THREE.Group();
  scene.add(mapGroup);
  let grid = null;

  // ---- map ----------------------------------------------------------------------------
  function clearMap() {
    for (const o of mapGroup.children) if (o.geometry && !Object.values(geos).includes(o.geometry)) o.geometry.dispose();
    mapGroup.clear();
    grid = null;
  }

  function shapeOf(corners) {
    const pts = corners.map(([x, y]) => new THREE.Vector2(x, y));
    if (pts.length > 2 && pts[0].equals(pts[pts.length - 1])) pts.pop();   // tolerate a closed ring
    return new THREE.Shape(pts);
  }

  function setMap(m) {
    clearMap();
    map = m && m.width > 0 && m.height > 0 ? m : null;
    fitPending = true;
    if (!map) return;
    const W = map.width, H = map.height;

    const floor = new THREE.Mesh(new THREE.PlaneGeometry(W, H), mats.floor);
    floor.position.set(W / 2, H / 2, 0);
    // Lab outline: a 10 cm high kerb just outside the lab rectangle (a shape with a hole).
    const rim = shapeOf([[-0.06, -0.06], [W + 0.06, -0.06], [W + 0.06, H + 0.06], [-0.06, H + 0.06]]);
    rim.holes.push(new THREE.Path([[0, 0], [0, H], [W, H], [W, 0]].map(([x, y]) => new THREE.Vector2(x, y))));
    mapGroup.add(floor, new THREE.Mesh(new THREE.ExtrudeGeometry(rim, { depth: 0.1, bevelEnabled: false }), mats.border));

    const lines = [];
    for (let x = 0; x <= W + 1e-6; x++) lines.push(x, 0, 0, x, H, 0);
    for (let y = 0; y <= H + 1e-6; y++) lines.push(0, y, 0, W, y, 0);
    grid = new THREE.LineSegments(new THREE.BufferGeometry().setAttribute("position", new THREE.Float32BufferAttribute(lines, 3)), mats.grid);
    grid.position.z = 0.004;
    grid.visible = showGrid;
    mapGroup.add(grid);

    // One extrusion per (kind, height): walls sharing a height cost one draw call.
    const groups = new Map();
    for (const w of map.walls || []) {
      if (!w.corners || w.corners.length < 3 || !(w.height > 0)) continue;
      const key = `${w.obstacle ? 1 : 0}:${w.height}`;
      if (!groups.has(key)) groups.set(key, { obstacle: !!w.obstacle, height: w.height, shapes: [] });
      groups.get(key).shapes.push(shapeOf(w.corners));
    }
    for (const g of groups.values()) {
      const geo = new THREE.ExtrudeGeometry(g.shapes, { depth: g.height, bevelEnabled: false });
      // Dark edges keep wall outlines readable where two faces have similar shade.
      mapGroup.add(new THREE.Mesh(geo, g.obstacle ? mats.obstacle : mats.wall),
        new THREE.LineSegments(new THREE.EdgesGeometry(geo, 30), mats.edge));
    }

    const disc = (x, y, r, mat, z) => {
      const d = new THREE.Mesh(geos.disc, mat);
      d.position.set(x, y, z); d.scale.set(r, r, 1);
      mapGroup.add(d);
    };
    for (const [x, y, r] of map.targets || []) disc(x, y, r, mats.target, 0.01);
    for (const [x, y, r] of map.checkpoints || []) disc(x, y, r, mats.checkpoint, 0.014);
    for (const [x, y, h] of map.beacons || []) {
      const pole = new THREE.Mesh(geos.pole, mats.beacon), ball = new THREE.Mesh(geos.ball, mats.beacon);
      pole.position.set(x, y, 0); pole.scale.z = Math.max(h, 0.01);
      ball.position.set(x, y, h);
      mapGroup.add(pole, ball);
    }
  }

  // ---- robots -------------------------------------------------------------------------
  // Buffers are reallocated with room to spare when the robot count outgrows them.
  let parts = null, capacity = 0;
  const farMesh = new THREE.Mesh(new THREE.BufferGeometry(), new THREE.MeshLambertMaterial({ vertexColors: true }));
  farMesh.frustumCulled = false;   // spans the whole crowd; culled per robot in layoutRobots
  farMesh.renderOrder = -1;
  scene.add(farMesh);

  function instanced(geo, mat, n) {
    const m = new THREE.InstancedMesh(geo, mat, n);
    m.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
    m.instanceColor = new THREE.InstancedBufferAttribute(new Float32Array(n * 3), 3).setUsage(THREE.DynamicDrawUsage);
    m.count = 0;
    m.frustumCulled = false;   // culled per robot in layoutRobots; its cached bounding sphere would go stale
    m.renderOrder = -2;        // see layoutRobots
    scene.add(m);
    return m;
  }

  function ensureCapacity(n) {
    if (n <= capacity && parts) return;
    capacity = Math.max(64, 2 ** Math.ceil(Math.log2(Math.max(n, 1))));
    if (parts) for (const m of Object.values(parts)) { scene.remove(m); m.dispose(); }
    parts = {
      box: instanced(geos.box, mats.body, capacity * 5),       // seat, backrest, footrest, 2 casters; doors
      wheel: instanced(geos.wheel, mats.body, capacity * 2),
      puck: instanced(geos.puck, mats.body, capacity),          // disc robots (plain Ciber-Rato)
      ghost: instanced(geos.box, mats.ghost, capacity),         // physical chairs' true poses
    };
    const nv = FAR.pos.length / 3, ni = FAR.index.length, index = new Uint32Array(capacity * ni);
    for (let k = 0; k < capacity; k++) for (let j = 0; j < ni; j++) index[k * ni + j] = FAR.index[j] + k * nv;
    const g = new THREE.BufferGeometry().setIndex(new THREE.BufferAttribute(index, 1));
    for (const name of ["position", "normal", "color"]) {
      g.setAttribute(name, new THREE.BufferAttribute(new Float32Array(capacity * nv * 3), 3).setUsage(THREE.DynamicDrawUsage));
    }
    farMesh.geometry.dispose();
    farMesh.geometry = g;
  }

  // Writes T(x,y) * Rz(heading) * T(px,py,pz) * S(sx,sy,sz) straight into an instance buffer;
  // composing matrices through Object3D would cost several times more per part.
  function put(mesh, x, y, c, s, px, py, pz, sx, sy, sz, col) {
    const i = mesh.count++, arr = mesh.instanceMatrix.array, o = i * 16;
    arr[o] = c * sx; arr[o + 1] = s * sx; arr[o + 2] = 0; arr[o + 3] = 0;
    arr[o + 4] = -s * sy; arr[o + 5] = c * sy; arr[o + 6] = 0; arr[o + 7] = 0;
    arr[o + 8] = 0; arr[o + 9] = 0; arr[o + 10] = sz; arr[o + 11] = 0;
    arr[o + 12] = x + c * px - s * py; arr[o + 13] = y + s * px + c * py; arr[o + 14] = pz; arr[o + 15] = 1;
    const ca = mesh.instanceColor.array;
    ca[i * 3] = col.r; ca[i * 3 + 1] = col.g; ca[i * 3 + 2] = col.b;
  }

  // Appends far chair k to the merged mesh: the template block scaled to the footprint
  // (normals by the inverse scale), turned to the heading and moved to (x, y).
  function putFar(k, x, y, c, s, mid, w, h, col) {
    const g = farMesh.geometry, P = g.attributes.position.array, N = g.attributes.normal.array, C = g.attributes.color.array;
    const n = FAR.pos.length, o = k * n;
    for (let j = 0; j < n; j += 3) {
      const lx = FAR.pos[j] * w + mid, ly = FAR.pos[j + 1] * h;
      P[o + j] = x + c * lx - s * ly; P[o + j + 1] = y + s * lx + c * ly; P[o + j + 2] = FAR.pos[j + 2];
      let nx = FAR.nor[j] / w, ny = FAR.nor[j + 1] / h, nz = FAR.nor[j + 2];
      const len = Math.hypot(nx, ny, nz); nx /= len; ny /= len;
      N[o + j] = c * nx - s * ny; N[o + j + 1] = s * nx + c * ny; N[o + j + 2] = nz / len;
      C[o + j] = col.r; C[o + j + 1] = col.g; C[o + j + 2] = col.b;
    }
  }

  const frustum = new THREE.Frustum(), sphere = new THREE.Sphere(), projView = new THREE.Matrix4();

  // Runs at render time because culling and level of detail depend on the camera. Software
  // WebGL pays for every triangle and pixel, so once many chairs are visible only the
  // nearest ones within DETAIL_RANGE get the full model.
  function layoutRobots(hidden) {
    const robots = (frame && frame.robots) || [];
    ensureCapacity(robots.length);
    for (const m of Object.values(parts)) m.count = 0;
    let nFar = 0;
    frustum.setFromProjectionMatrix(projView.multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse));
    const vis = [];
    for (const r of robots) {
      if (r === hidden || !(r.width > 0 && r.height > 0)) continue;
      sphere.center.set(r.x, r.y, 0.5); sphere.radius = 0.5 * Math.hypot(r.width, r.height) + 1;
      if (frustum.intersectsSphere(sphere)) vis.push(r);
    }
    // Nearest first, and robots before the map (renderOrder), so GPUs can reject hidden
    // fragments early; the order also picks the chairs that get the full model.
    const p = camera.position, d2 = (r) => (r.x - p.x) ** 2 + (r.y - p.y) ** 2;
    const order = vis.map(d2), idx = Array.from(vis.keys()).sort((i, j) => order[i] - order[j]);
    const near = vis.length > DETAILED_NEAREST ? Math.min(DETAIL_RANGE ** 2, order[idx[DETAILED_NEAREST - 1]]) : Infinity;

    for (const i of idx) {
      const r = vis[i];
      const a = r.heading * DEG, c = Math.cos(a), s = Math.sin(a), x = r.x, y = r.y;
      const w = r.width, h = r.height, front = r.com * w, back = front - w, mid = (front + back) / 2;
      const col = r.flags & 1 ? HIT_COLOR : r.kind === 2 ? DOOR_COLOR : CHAIR_COLOR;
      if (r.kind === 2) { put(parts.box, x, y, c, s, mid, 0, DOOR_HEIGHT / 2, w, h, DOOR_HEIGHT, col); continue; }
      if (r.flags & ROBOT_DISC) {
        // A disc robot: a cylinder of its diameter on its centre, a dark nose along the heading.
        put(parts.puck, x, y, c, s, 0, 0, PUCK_HEIGHT / 2, w, w, PUCK_HEIGHT, col);
        put(parts.box, x, y, c, s, 0.3 * w, 0, PUCK_HEIGHT + 0.02, 0.35 * w, 0.08 * w, 0.04, TYRE_COLOR);
        continue;
      }
      if (order[i] > near) { putFar(nFar++, x, y, c, s, mid, w, h, col); continue; }
      // Full chair. Proportions follow the footprint; the drive wheels sit on the pose point
      // (centre of movement) unless that would push them out of the footprint.
      const R = Math.min(0.3, 0.3 * w, 0.45 * h), t = Math.min(0.05, 0.1 * h);
      const wx = Math.min(Math.max(0, back + R), front - R), inner = h - 2 * t;
      put(parts.box, x, y, c, s, back + 0.4 * w, 0, 0.5, 0.6 * w, inner, 0.1, col);                                 // seat
      put(parts.box, x, y, c, s, back + 0.08 * w, 0, (0.55 + CHAIR_TOP) / 2, 0.08 * w, inner, CHAIR_TOP - 0.55, col); // backrest
      put(parts.box, x, y, c, s, front - 0.08 * w, 0, 0.12, 0.16 * w, 0.6 * h, 0.04, col);                          // footrest
      put(parts.wheel, x, y, c, s, wx, h / 2 - t / 2, R, R, t, R, TYRE_COLOR);
      put(parts.wheel, x, y, c, s, wx, -h / 2 + t / 2, R, R, t, R, TYRE_COLOR);
      const rc = Math.min(0.08, 0.1 * w), cx = front - 0.25 * w;   // casters: small dark blocks
      put(parts.box, x, y, c, s, cx, 0.3 * h, rc, 2 * rc, 0.04, 2 * rc, TYRE_COLOR);
      put(parts.box, x, y, c, s, cx, -0.3 * h, rc, 2 * rc, 0.04, 2 * rc, TYRE_COLOR);
    }
    // Ghosts: few (one per physical chair with a test bench), so neither culled nor simplified.
    for (const g of (frame && frame.chairs) || []) {
      const r = g.ghost && robots.find((r) => r.id === g.id);
      if (!r || !(r.width > 0 && r.height > 0)) continue;
      const a = g.ghost[2] * DEG, w = r.width, h = r.flags & ROBOT_DISC ? r.width : r.height;
      const mid = r.flags & ROBOT_DISC ? 0 : (r.com - 0.5) * w;
      put(parts.ghost, g.ghost[0], g.ghost[1], Math.cos(a), Math.sin(a), mid, 0, CHAIR_TOP / 2, w, h, CHAIR_TOP, GHOST_COLOR);
    }
    // Upload only the used part of each buffer: they are sized for the peak robot count.
    const dirty = (attr, n) => { if (n > 0) { attr.clearUpdateRanges(); attr.addUpdateRange(0, n); attr.needsUpdate = true; } };
    for (const m of Object.values(parts)) { dirty(m.instanceMatrix, m.count * 16); dirty(m.instanceColor, m.count * 3); }
    const fg = farMesh.geometry;
    for (const name of ["position", "normal", "color"]) dirty(fg.attributes[name], nFar * FAR.pos.length);
    fg.setDrawRange(0, nFar * FAR.index.length);
  }

  // The robot the first/third-person camera rides; null when absent (free camera then).
  // With no id chosen, the first chair is used (a door would make a poor vantage point).
  function followed() {
    const robots = (frame && frame.robots) || [];
    if (robotId === null || robotId === undefined) return robots.find(r => r.kind !== 2) || robots[0] || null;
    return robots.find(r => r.id === robotId) || null;
  }

  // ---- labels -------------------------------------------------------------------------
  const labelMats = new Map();   // text -> SpriteMaterial, made once per distinct name
  const sprites = [];            // reusable pool; only the visible ones are positioned

  function labelMaterial(text) {
    let m = labelMats.get(text);
    if (m) return m;
    const cv = document.createElement("canvas"), g = cv.getContext("2d"), font = "bold 36px sans-serif";
    g.font = font;
    cv.width = Math.ceil(g.measureText(text).width) + 20; cv.height = 48;
    g.font = font;   // resizing the canvas resets the context state
    g.fillStyle = "rgba(255,255,255,0.85)"; g.fillRect(0, 0, cv.width, cv.height);
    g.fillStyle = "#111"; g.textBaseline = "middle"; g.fillText(text, 10, cv.height / 2 + 2);
    const tex = new THREE.CanvasTexture(cv);
    tex.colorSpace = THREE.SRGBColorSpace;
    // sizeAttenuation off: labels keep a constant pixel size so they stay legible from afar.
    m = new THREE.SpriteMaterial({ map: tex, sizeAttenuation: false, depthWrite: false });
    m.userData.aspect = cv.width / cv.height;
    labelMats.set(text, m);
    return m;
  }

  function layoutLabels(hidden) {
    let shown = 0;
    if (showLabels && frame && frame.robots) {
      let list = frame.robots.filter(r => r !== hidden);
      if (list.length > LABEL_MAX) {
        // Only the nearest ones in front of the camera: one draw call per sprite (and a
        // texture per new name) would otherwise dominate the frame.
        const p = camera.position, d = camera.getWorldDirection(new THREE.Vector3());
        list = list.map(r => [r, (r.x - p.x) ** 2 + (r.y - p.y) ** 2 + p.z ** 2, (r.x - p.x) * d.x + (r.y - p.y) * d.y - p.z * d.z])
          .filter(e => e[2] > 0).sort((a, b) => a[1] - b[1]).slice(0, LABEL_MAX).map(e => e[0]);
      }
      const sy = LABEL_PX / Math.max(height, 1) * 2 * Math.tan(camera.fov * DEG / 2);
      for (const r of list) {
        let sp = sprites[shown];
        if (!sp) {
          sp = new THREE.Sprite();
          sp.center.set(0.5, 0);   // anchor the bottom edge above the robot
          sprites.push(sp); scene.add(sp);
        }
        sp.material = labelMaterial(names.get(r.id) ?? `#${r.id}`);
        sp.position.set(r.x, r.y, (r.kind === 2 ? DOOR_HEIGHT : CHAIR_TOP) + 0.15);
        sp.scale.set(sy * sp.material.userData.aspect, sy, 1);
        sp.visible = true;
        shown++;
      }
    }
    for (let i = shown; i < sprites.length; i++) sprites[i].visible = false;
  }

  // ---- cameras ------------------------------------------------------------------------
  const orbit = { target: new THREE.Vector3(), dist: 30, az: -Math.PI / 2, el: 55 * DEG };

  // Whole lab seen from the south at an angle; the lab's near edge is closer than the
  // target, hence the correction terms.
  function fitOrbit() {
    if (!map) return;
    orbit.target.set(map.width / 2, map.height / 2, 0);
    orbit.az = -Math.PI / 2; orbit.el = 55 * DEG;
    const tv = Math.tan(FOV.free * DEG / 2), th = tv * camera.aspect;
    orbit.dist = 1.08 * Math.max(map.width / 2 / th + map.height / 2 * Math.cos(orbit.el),
      map.height / 2 * Math.sin(orbit.el) / tv + map.height / 2 * Math.cos(orbit.el));
    fitPending = false;
  }

  function placeCamera(r) {
    const fov = r ? FOV[mode] : FOV.free;
    if (camera.fov !== fov) { camera.fov = fov; camera.updateProjectionMatrix(); }
    if (r) {
      const a = r.heading * DEG, c = Math.cos(a), s = Math.sin(a);
      if (mode === "first") {
        const f = r.com * r.width;
        camera.position.set(r.x + c * f, r.y + s * f, EYE_HEIGHT);
        camera.lookAt(r.x + c * (f + 10), r.y + s * (f + 10), EYE_HEIGHT);
      } else {
        camera.position.set(r.x - 3 * c, r.y - 3 * s, 2.0);
        camera.lookAt(r.x, r.y, 0.6);
      }
      return;
    }
    if (fitPending) fitOrbit();
    const o = orbit, ce = Math.cos(o.el);
    camera.position.set(o.target.x + o.dist * ce * Math.cos(o.az), o.target.y + o.dist * ce * Math.sin(o.az), o.target.z + o.dist * Math.sin(o.el));
    camera.lookAt(o.target);
  }

  // Orbit controller for the free camera: left drag rotates, right or shift+left pans,
  // wheel zooms. Ignored while a robot camera is active.
  let drag = null;
  const onDown = (e) => {
    if (!usingFree) return;
    drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.button === 1 || (e.button === 0 && e.shiftKey) };
    canvas.setPointerCapture(e.pointerId);
  };
  const onMove = (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      // Metres per pixel at the target's distance, so the floor follows the pointer.
      const k = orbit.dist * 2 * Math.tan(camera.fov * DEG / 2) / Math.max(canvas.clientHeight, 1);
      const sa = Math.sin(orbit.az), ca = Math.cos(orbit.az);
      orbit.target.x += (sa * dx - ca * dy / Math.max(Math.sin(orbit.el), 0.2)) * k;
      orbit.target.y += (-ca * dx - sa * dy / Math.max(Math.sin(orbit.el), 0.2)) * k;
    } else {
      orbit.az -= dx * 0.008;
      orbit.el = Math.min(Math.max(orbit.el + dy * 0.008, 2 * DEG), 89 * DEG);
    }
  };
  const onUp = (e) => { if (drag && canvas.hasPointerCapture(e.pointerId)) canvas.releasePointerCapture(e.pointerId); drag = null; };
  const onWheel = (e) => {
    if (!usingFree) return;
    e.preventDefault();
    // Proportional to the wheel delta (lines count as ~33 px) so trackpads zoom smoothly.
    const dy = e.deltaMode === 1 ? e.deltaY * 33 : e.deltaY;
    orbit.dist = Math.min(Math.max(orbit.dist * Math.exp(Math.max(-1, Math.min(1, dy / 100)) * 0.12), 0.5), 1000);
  };
  const onMenu = (e) => { if (usingFree) e.preventDefault(); };
  canvas.addEventListener("pointerdown", onDown);
  canvas.addEventListener("pointermove", onMove);
  canvas.addEventListener("pointerup", onUp);
  canvas.addEventListener("pointercancel", onUp);
  canvas.addEventListener("wheel", onWheel, { passive: false });
  canvas.addEventListener("contextmenu", onMenu);

  // ---- API ----------------------------------------------------------------------------
  function render() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (w === 0 || h === 0) return;   // hidden canvas: nothing to draw
    if (w !== width || h !== height) {
      width = w; height = h;
      renderer.setSize(w, h, false);
      camera.aspect = w / h; camera.updateProjectionMatrix();
    }
    const r = mode === "free" ? null : followed();
    usingFree = !r;
    placeCamera(r);
    camera.updateMatrixWorld();
    const hidden = mode === "first" ? r : null;   // the rider's own chair would fill the view
    layoutRobots(hidden);
    layoutLabels(hidden);
    renderer.render(scene, camera);
  }

  ensureCapacity(0);
  return {
    setMap,
    update(f, n) {
      // Only stored: instances are laid out in render(), which knows the camera.
      frame = f && Array.isArray(f.robots) ? f : null;
      if (n instanceof Map) names = n;
    },
    setCamera(m, id) {
      mode = m === "first" || m === "third" ? m : "free";
      robotId = id ?? null;
    },
    setShowGrid(on) { showGrid = !!on; if (grid) grid.visible = showGrid; },
    setShowLabels(on) { showLabels = !!on; },
    render,
    dispose() {
      canvas.removeEventListener("pointerdown", onDown);
      canvas.removeEventListener("pointermove", onMove);
      canvas.removeEventListener("pointerup", onUp);
      canvas.removeEventListener("pointercancel", onUp);
      canvas.removeEventListener("wheel", onWheel);
      canvas.removeEventListener("contextmenu", onMenu);
      clearMap();
      for (const m of Object.values(parts)) m.dispose();
      farMesh.geometry.dispose(); farMesh.material.dispose();
      for (const m of labelMats.values()) { m.map.dispose(); m.dispose(); }
      labelMats.clear();
      for (const g of Object.values(geos)) g.dispose();
      for (const m of Object.values(mats)) m.dispose();
      renderer.dispose();
    },
  };
}
