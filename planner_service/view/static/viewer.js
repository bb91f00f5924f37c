// dexroll plan viewer: draws the scene that planner_service/view/scene.py computed (every
// pose at every sample, palm frame, metres, quaternions x y z w) with three.js (the global
// THREE of three.min.js). It interpolates between samples (positions linearly, rotations
// by slerp) and computes nothing else. window.dexroll is the page's handle for scripts and
// tests: ready, duration, setTime(s), time(), play(), pause(), playing(), and for a gait
// schedulePoint(contact, s): where the timeline's schedule draws a contact at time s.
(function () {
  "use strict";
  const T = window.THREE;
  const data = JSON.parse(document.getElementById("dexroll-scene").textContent);
  const times = data.t;
  const n = times.length;
  const t0 = times[0];
  const t1 = times[n - 1];
  const el = (id) => document.getElementById(id);
  const api = { ready: false, duration: t1 - t0, error: null };
  window.dexroll = api;

  function fail(message) {
    api.error = message;
    el("message").textContent = message;
    el("message").hidden = false;
    console.error("dexroll viewer: " + message);
  }

  let renderer;
  try {
    renderer = new T.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    fail("WebGL is not available in this browser: " + e.message);
    return;
  }
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.outputColorSpace = T.SRGBColorSpace;
  const view = el("view");
  view.appendChild(renderer.domElement);

  const scene = new T.Scene();
  scene.background = new T.Color(0xf4f5f7);
  scene.add(new T.HemisphereLight(0xffffff, 0x8d8d8d, 2.2));
  const sun = new T.DirectionalLight(0xffffff, 2.0);
  sun.position.set(1, -1.5, 3);
  scene.add(sun);

  // -- the camera: the whole plan in view, looking from the front, right and above ------
  const R = data.bounds.radius;
  const centre = new T.Vector3().fromArray(data.bounds.center);
  const camera = new T.PerspectiveCamera(35, 1, R / 200, R * 200);
  camera.up.set(0, 0, 1);
  const dir = new T.Vector3(1.1, -1.7, 1.2).normalize();
  camera.position.copy(centre).addScaledVector(dir, (0.95 * R) / Math.sin((35 / 2) * Math.PI / 180));
  const controls = new T.OrbitControls(camera, renderer.domElement);
  controls.target.copy(centre);
  controls.update();

  // -- pose tracks -----------------------------------------------------------------------
  const qa = new T.Quaternion();
  const qb = new T.Quaternion();
  function place(obj, pose, k, a) {
    const m = pose.p.length / 3;
    const i = Math.min(k, m - 1);
    const j = Math.min(k + 1, m - 1);
    const p = pose.p;
    const q = pose.q;
    obj.position.set(p[3 * i] + a * (p[3 * j] - p[3 * i]),
                     p[3 * i + 1] + a * (p[3 * j + 1] - p[3 * i + 1]),
                     p[3 * i + 2] + a * (p[3 * j + 2] - p[3 * i + 2]));
    qa.set(q[4 * i], q[4 * i + 1], q[4 * i + 2], q[4 * i + 3]);
    qb.set(q[4 * j], q[4 * j + 1], q[4 * j + 2], q[4 * j + 3]);
    obj.quaternion.slerpQuaternions(qa, qb, a);
  }
  function vec(arr, k, a, out) {
    const j = Math.min(k + 1, arr.length / 3 - 1);
    return out.set(arr[3 * k] + a * (arr[3 * j] - arr[3 * k]),
                   arr[3 * k + 1] + a * (arr[3 * j + 1] - arr[3 * k + 1]),
                   arr[3 * k + 2] + a * (arr[3 * j + 2] - arr[3 * k + 2]));
  }
  function line(points, color, width) {
    const g = new T.BufferGeometry();
    g.setAttribute("position", new T.BufferAttribute(new Float32Array(points), 3));
    const l = new T.Line(g, new T.LineBasicMaterial({ color: color, linewidth: width || 1 }));
    l.frustumCulled = false;
    return l;
  }
  const material = (rgba) => new T.MeshStandardMaterial({
    color: new T.Color(rgba[0], rgba[1], rgba[2]), roughness: 0.6, metalness: 0.1,
    transparent: rgba[3] < 1, opacity: rgba[3] });

  function shapeMesh(shape, mat) {
    let g;
    switch (shape.kind) {
      case "box": g = new T.BoxGeometry(shape.size[0], shape.size[1], shape.size[2]); break;
      case "cylinder":
        g = new T.CylinderGeometry(shape.radius, shape.radius, shape.length, 24);
        g.rotateX(Math.PI / 2); break;  // three's cylinders lie along y, the model's along z
      case "capsule":
        g = new T.CapsuleGeometry(shape.radius, shape.length, 6, 16);
        g.rotateX(Math.PI / 2); break;
      case "sphere": g = new T.SphereGeometry(shape.radius, 24, 16); break;
      case "ellipsoid":
        g = new T.SphereGeometry(1, 24, 16);
        g.scale(shape.semi_axes[0], shape.semi_axes[1], shape.semi_axes[2]); break;
      default: return null;
    }
    return new T.Mesh(g, mat);
  }

  // -- the palm --------------------------------------------------------------------------
  const palmTraces = [];
  if (data.palm) {
    const h = data.palm.half_extent;
    const palm = new T.Group();
    palm.position.set(data.palm.center[0], data.palm.center[1], 0);
    scene.add(palm);
    const plate = new T.Mesh(new T.PlaneGeometry(2 * h, 2 * h),
      new T.MeshStandardMaterial({ color: 0xd9dce3, roughness: 0.9, side: T.DoubleSide }));
    plate.position.z = -1e-4;
    palm.add(plate);
    const grid = new T.GridHelper(2 * h, Math.max(2, Math.round((2 * h) / data.palm.grid)),
                                  0xaab0bc, 0xbfc4ce);
    grid.rotateX(Math.PI / 2);
    palm.add(grid);
  }

  // -- the object: a checkered ellipsoid with its axes -----------------------------------
  const object = new T.Group();
  scene.add(object);
  const tex = (function () {
    const c = document.createElement("canvas");
    c.width = 512; c.height = 256;
    const g = c.getContext("2d");
    for (let i = 0; i < 12; i++) {
      for (let j = 0; j < 6; j++) {
        g.fillStyle = (i + j) % 2 ? "#f2f2f2" : "#3b5bdb";
        g.fillRect(i * c.width / 12, j * c.height / 6, c.width / 12, c.height / 6);
      }
    }
    g.fillStyle = "#e03131";  // one meridian, to see the turn about the polar axis
    g.fillRect(0, 0, c.width / 48, c.height);
    const t = new T.CanvasTexture(c);
    t.colorSpace = T.SRGBColorSpace;
    return t;
  })();
  // the object: an ellipsoid (a ball: equal semi-axes), a capsule or a superellipsoid
  const shape = data.object.shape;
  const capsule = shape.kind === "capsule";
  const ax = capsule ? [shape.radius, shape.radius, shape.length / 2 + shape.radius]
    : shape.semi_axes;
  const ballGeom = capsule ? new T.CapsuleGeometry(shape.radius, shape.length, 16, 48)
    : new T.SphereGeometry(1, 64, 48);
  ballGeom.rotateX(Math.PI / 2);  // three's poles are on y; the object's axis is its z
  if (shape.kind === "superellipsoid") {  // each unit direction d to rho(d) d
    const pos = ballGeom.attributes.position, n = shape.exponent;
    for (let i = 0; i < pos.count; i++) {
      const d = [pos.getX(i), pos.getY(i), pos.getZ(i)];
      const s = d.reduce((acc, x, k) => acc + Math.pow(Math.abs(x / ax[k]), n), 0);
      const rho = Math.pow(s, -1 / n);
      pos.setXYZ(i, rho * d[0], rho * d[1], rho * d[2]);
    }
    ballGeom.computeVertexNormals();
  }
  const ball = new T.Mesh(ballGeom, new T.MeshStandardMaterial({ map: tex, roughness: 0.5 }));
  if (!capsule && shape.kind !== "superellipsoid") ball.scale.set(ax[0], ax[1], ax[2]);
  object.add(ball);
  const axes = new T.Group();  // the object's x, y, z: red, green, blue rods
  const rod = 1.45 * Math.max(ax[0], ax[1], ax[2]);
  [[0xd62828, [0, 0, -Math.PI / 2]], [0x2a9d3f, [0, 0, 0]], [0x1d4ed8, [Math.PI / 2, 0, 0]]]
    .forEach(([color, rot]) => {
      const g = new T.CylinderGeometry(0.035 * rod, 0.035 * rod, rod, 12);
      g.translate(0, rod / 2, 0);  // from the centre out along +y, then turned onto the axis
      const m = new T.Mesh(g, new T.MeshStandardMaterial({ color: color, roughness: 0.5 }));
      m.rotation.set(rot[0], rot[1], rot[2]);
      axes.add(m);
    });
  object.add(axes);

  // -- contacts: markers, traces on the object (and palm), friction cones ----------------
  const cones = [];
  const markers = [];
  const traces = [];
  const mr = 0.12 * Math.min(ax[0], ax[1], ax[2]);
  const coneHeight = 1.2 * Math.max(ax[0], ax[1], ax[2]);
  for (const c of data.contacts) {
    const m = new T.Mesh(new T.SphereGeometry(mr, 16, 12),
                         new T.MeshBasicMaterial({ color: c.color }));
    scene.add(m);
    markers.push(m);
    const onObject = line(c.trace, c.color, 2);
    object.add(onObject);
    traces.push(onObject);
    if (c.body === "palm") {
      const onPalm = line(c.point.map((v, i) => (i % 3 === 2 ? 2e-4 : v)), c.color, 2);
      scene.add(onPalm);
      traces.push(onPalm);
      palmTraces.push(onPalm);
    }
    if (data.cone_half_angle) {
      const g = new T.ConeGeometry(coneHeight * Math.tan(data.cone_half_angle), coneHeight,
                                   32, 1, true);
      g.translate(0, -coneHeight / 2, 0);  // apex at the contact, opening along -y (the normal)
      const cone = new T.Mesh(g, new T.MeshBasicMaterial({
        color: c.color, transparent: true, opacity: 0.22, side: T.DoubleSide,
        depthWrite: false }));
      scene.add(cone);
      cones.push(cone);
    }
  }

  // -- fingertips: pads or round tips (tagged records) with their contact traces --------
  const tips = [];
  for (const f of data.fingertips) {
    const g = new T.Group();
    scene.add(g);
    const s = f.shape;
    if (s.kind === "pad") {
      const box = new T.BoxGeometry(2 * s.half_size, 2 * s.half_size, s.thickness);
      box.translate(0, 0, -s.thickness / 2);  // the pad's surface is its frame's z = 0
      g.add(new T.Mesh(box, new T.MeshStandardMaterial({
        color: 0x2b2b2b, roughness: 0.9, transparent: true, opacity: 0.55, depthWrite: false })));
      const edges = new T.LineSegments(new T.EdgesGeometry(box),
                                       new T.LineBasicMaterial({ color: f.color }));
      g.add(edges);
    } else {  // a round tip (sphere, capsule, ellipsoid) in its own frame
      const m = shapeMesh(s, material([0.17, 0.17, 0.17, 0.8]));
      if (m) g.add(m);
    }
    if (f.trace) {
      const pad = s.kind === "pad";
      const tr = line(pad ? f.trace.map((v, i) => (i % 3 === 2 ? v - 2e-4 : v)) : f.trace,
                      f.color, 2);
      if (!pad) {  // on the curved surface itself: drawn over it
        tr.material.depthTest = false;
        tr.renderOrder = 1;
      }
      g.add(tr);
      traces.push(tr);
    }
    tips.push({ group: g, pose: f.pose });
  }

  // -- the fingers' links ----------------------------------------------------------------
  const links = [];
  for (const b of data.bodies) {
    const m = shapeMesh(b.shape, material(b.color));
    if (!m) continue;
    scene.add(m);
    links.push({ mesh: m, pose: b.pose });
    place(m, b.pose, 0, 0);
  }

  // -- a gait's contact schedule under the timeline: a row per contact, its colour where
  // it touches (faded in its force ramps, none while lifted clear), the phases above ----
  const phases = data.phases || null;
  const sched = el("schedule");
  const ROW = 16;
  const HEAD = 18;
  const LABEL = 76;
  const PHASE_FILL = { roll: "#e7f0fd", unload: "#f1f3f5", swing: "#fff0d9", load: "#f1f3f5" };
  const schedX = (s) => LABEL + ((s - t0) / Math.max(t1 - t0, 1e-9)) *
    Math.max((sched.width || 800) - LABEL - 8, 1);
  const schedY = (i) => HEAD + i * ROW + ROW / 2;
  function drawSchedule() {
    if (!phases) return;
    const w = sched.clientWidth || 800;
    const h = HEAD + data.contacts.length * ROW + 4;
    if (sched.width !== w) sched.width = w;
    if (sched.height !== h) sched.height = h;
    const g = sched.getContext("2d");
    g.clearRect(0, 0, w, h);
    g.fillStyle = "#ffffff";
    g.fillRect(0, 0, w, h);
    g.font = "11px system-ui, sans-serif";
    g.textBaseline = "middle";
    for (const p of phases) {  // the phases: shaded, named, their boundaries
      const a = schedX(p.start);
      const b = schedX(p.end);
      g.fillStyle = PHASE_FILL[p.kind] || "#f1f3f5";
      g.fillRect(a, 0, b - a, HEAD - 2);
      g.fillStyle = "#1d232f";
      const name = p.kind === "roll" ? (p.lifted ? "roll, " + p.lifted + " swings" : "roll")
        : p.kind === "swing" ? p.lifted + " lifted" : "";
      if (name && g.measureText(name).width < b - a - 4) g.fillText(name, a + 2, HEAD / 2);
    }
    data.contacts.forEach((c, i) => {
      const y = schedY(i) - ROW / 2 + 2;
      g.globalAlpha = 1;
      g.fillStyle = "#1d232f";
      g.fillText(c.name, 4, schedY(i));
      g.fillStyle = c.color;
      for (let k = 0; k + 1 < n; k++) {
        const act = c.active ? Math.min(c.active[k], c.active[k + 1]) : 1;
        if (act <= 0) continue;
        g.globalAlpha = act;
        g.fillRect(schedX(times[k]), y, schedX(times[k + 1]) - schedX(times[k]) + 0.5, ROW - 4);
      }
      g.globalAlpha = 1;
    });
    g.strokeStyle = "#868e96";
    g.lineWidth = 1;
    for (const p of phases) {
      const x = Math.round(schedX(p.start)) + 0.5;
      g.beginPath(); g.moveTo(x, 0); g.lineTo(x, h); g.stroke();
    }
    const x = Math.round(schedX(now)) + 0.5;  // the time shown
    g.strokeStyle = "#1d232f";
    g.lineWidth = 2;
    g.beginPath(); g.moveTo(x, 0); g.lineTo(x, h); g.stroke();
  }
  function phaseAt(s) {
    if (!phases) return null;
    for (const p of phases) if (s <= p.end) return p;
    return phases[phases.length - 1];
  }
  if (phases) {  // sized before the first resize: the 3D view takes what is left
    sched.hidden = false;
    sched.width = sched.clientWidth || 800;
    sched.height = HEAD + data.contacts.length * ROW + 4;
    sched.addEventListener("click", (e) => {
      const r = sched.getBoundingClientRect();
      const f = (e.clientX - r.left - LABEL) / Math.max(sched.width - LABEL - 8, 1);
      api.setTime(t0 + Math.min(Math.max(f, 0), 1) * (t1 - t0));
    });
    api.schedulePoint = (name, s) => {
      const i = data.contacts.findIndex((c) => c.name === name);
      return i < 0 ? null : [schedX(s), schedY(i)];
    };
  }

  // -- time ------------------------------------------------------------------------------
  let now = t0;
  let playing = false;
  let speed = 1;
  const nv = new T.Vector3();
  const down = new T.Vector3(0, -1, 0);
  function sampleAt(s) {
    let lo = 0;
    let hi = n - 1;
    if (s <= times[0]) return [0, 0];
    if (s >= times[hi]) return [hi, 0];
    while (hi - lo > 1) {
      const mid = (lo + hi) >> 1;
      if (times[mid] <= s) lo = mid; else hi = mid;
    }
    return [lo, (s - times[lo]) / (times[lo + 1] - times[lo])];
  }
  const fmtDeg = (rad) => (rad * 180 / Math.PI).toFixed(2) + "\u00b0";
  function update() {
    const [k, a] = sampleAt(now);
    place(object, data.object.pose, k, a);
    const lifted = [];
    data.contacts.forEach((c, i) => {
      vec(c.point, k, a, markers[i].position);
      // a gait's fingertip off the ball: no contact marker, no cone
      const on = !c.active || c.active[k] >= 0.5;
      if (!on) lifted.push(c.name);
      markers[i].visible = on;
      if (cones.length) {
        cones[i].position.copy(markers[i].position);
        cones[i].quaternion.setFromUnitVectors(down, vec(c.normal, k, a, nv).normalize());
        cones[i].visible = on && el("show-cones").checked;
      }
    });
    el("lifted").textContent = lifted.length ? "lifted: " + lifted.join(", ") : "";
    const ph = phaseAt(now);
    el("phase").textContent = !ph ? "" : ph.lifted ?
      ph.kind + " (" + ph.lifted + (ph.kind === "swing" ? " lifted clear)" :
        ph.kind === "roll" ? " swinging)" : ")") : ph.kind;
    drawSchedule();
    for (const tr of traces) tr.geometry.setDrawRange(0, k + 1);
    for (const tip of tips) place(tip.group, tip.pose, k, a);
    for (const l of links) if (l.pose.p.length > 3) place(l.mesh, l.pose, k, a);
    el("clock").textContent = "t = " + now.toFixed(3) + " s / " + t1.toFixed(3) + " s";
    el("slider").value = String(now);
    if (data.grasp_angle) {
      const g = data.grasp_angle;
      const j = Math.min(k + 1, n - 1);
      el("grasp").textContent = "grasp angle " + fmtDeg(g[k] + a * (g[j] - g[k])) +
        (data.cone_half_angle ? "  (friction cone " + fmtDeg(data.cone_half_angle) + ")" : "");
    }
    renderer.render(scene, camera);
  }

  function resize() {
    if (phases) drawSchedule();  // its height first
    const w = view.clientWidth || 800;
    const h = view.clientHeight || 600;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    renderer.render(scene, camera);
  }

  // -- controls --------------------------------------------------------------------------
  const slider = el("slider");
  slider.min = String(t0);
  slider.max = String(t1);
  slider.step = "any";
  slider.addEventListener("input", () => { api.pause(); now = parseFloat(slider.value); update(); });
  el("play").addEventListener("click", () => (playing ? api.pause() : api.play()));
  el("speed").addEventListener("change", (e) => { speed = parseFloat(e.target.value); });
  const toggle = (id, objs) => el(id).addEventListener("change", (e) => {
    for (const o of objs) o.visible = e.target.checked;
    renderer.render(scene, camera);
  });
  toggle("show-cones", cones);
  toggle("show-traces", traces);
  toggle("show-axes", [axes]);
  toggle("show-links", links.map((l) => l.mesh));
  if (!cones.length) el("show-cones").parentElement.hidden = true;
  if (!links.length) el("show-links").parentElement.hidden = true;
  controls.addEventListener("change", () => renderer.render(scene, camera));
  window.addEventListener("resize", resize);

  let last = null;
  function frame(ms) {
    if (!playing) { last = null; return; }
    if (last !== null) {
      now += ((ms - last) / 1000) * speed;
      if (now > t1) now = t0 + ((now - t0) % Math.max(t1 - t0, 1e-9));
    }
    last = ms;
    update();
    requestAnimationFrame(frame);
  }
  api.setTime = (s) => { api.pause(); now = Math.min(Math.max(s, t0), t1); update(); return now; };
  api.time = () => now;
  api.playing = () => playing;
  api.play = () => {
    if (playing) return;
    playing = true;
    el("play").textContent = "\u275a\u275a pause";
    requestAnimationFrame(frame);
  };
  api.pause = () => { playing = false; el("play").textContent = "\u25b6 play"; };

  resize();
  update();
  api.ready = true;
  document.body.dataset.ready = "true";
  if (!/[?&#]paused\b/.test(window.location.href) && !navigator.webdriver) api.play();
})();
