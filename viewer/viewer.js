/* fieldgrip web viewer: one scene of fieldgripd in 3D, driven through the daemon's HTTP API.
 *
 * Plain ES2017 with the global THREE of Debian's three.min.js (r111), loaded before this file.
 * World frame = the robot's base frame (+z up, metres), as every pose of the API: the camera's
 * up vector is +z and nothing is converted.
 *
 * What it draws and where the data comes from:
 *   - the workspace box and every frame's camera frustum: GET /v1/scenes/{s}, .../frames;
 *     clicking a frustum shows the frame's photo (GET .../frames/{i}/image) beside the field's
 *     render from that pose (POST .../render);
 *   - the field as one THREE.Points of the solid voxels: GET .../points (the binary FGPC
 *     layout of proto/openapi.yaml); a heatmap (POST .../heatmap, format ply: the occupied
 *     voxels with the daemon's turbo colours) recolours the same colour attribute in place,
 *     so a query costs no new geometry;
 *   - tasks, their demos and the top-k grasps as the gripper model's boxes (POST .../grasps
 *     returns the boxes the collision check used), executed in dry run or for real;
 *   - a training job's progress from its Server-Sent Events, read with fetch() so that the
 *     token can be sent (EventSource cannot send headers).
 * Every failed request's message goes to the red banner at the top; nothing fails silently.
 *
 * For tests and scripts, window.fgViewer exposes the state and a few actions (see the end). */
'use strict';

(function () {
  const $ = (id) => document.getElementById(id);
  const link = new URLSearchParams(location.search);
  const TOKEN_KEY = 'fieldgrip.token';
  const DEFAULT_FOV_DEG = 50;

  /* ---------------------------------------------------------------- state */

  const state = {
    token: sessionStorage.getItem(TOKEN_KEY) || localStorage.getItem(TOKEN_KEY) || '',
    phase: 'loading',  // loading | need-token | ready
    busy: 0,           // requests in flight
    errors: [],        // every message shown in the banner, oldest first
    scene: null,       // GET /v1/scenes/{s}
    frames: [],        // GET .../frames
    cloud: null,       // the parsed point cloud (parseFgpc)
    heat: null,        // {lo, hi, best: [x, y, z], bestScore, scored}
    query: null,       // the query keys of the last heatmap (text or embedding, negatives)
    tasks: [],
    grasps: [],
    gripper: null,     // the boxes of the last grasp reply
    selectedGrasp: -1,
    frame: -1,         // the frame whose photo is shown
    job: null,         // the last job event's data
    progressEvents: 0,
    loadedMs: null,    // from navigation start to the first point cloud drawn
    heatmapMs: null,   // from navigation start to the first heatmap drawn
    version: 0,        // bumped by every change the 3D view shows
    drawnVersion: -1,  // the version the last frame drew
  };
  const waiters = [];  // fgViewer.waitFor's pending predicates

  /* Called after every change: refreshes the page's data-state and wakes fgViewer.waitFor. */
  function changed(redraw) {
    if (redraw) state.version++;
    document.body.dataset.state = state.phase;
    document.body.dataset.busy = String(state.busy);
    for (let i = waiters.length - 1; i >= 0; i--) {
      let ok = false;
      try { ok = waiters[i].pred(); } catch (e) { ok = false; }
      if (ok) {
        clearTimeout(waiters[i].timer);
        waiters.splice(i, 1)[0].resolve(status());
      }
    }
  }

  /* ---------------------------------------------------------------- errors and requests */

  class ApiError extends Error {
    constructor(status, code, message) {
      super(message);
      this.status = status;
      this.code = code;
    }
  }

  function showError(e) {
    const msg = e instanceof ApiError || e instanceof Error ? e.message : String(e);
    state.errors.push(msg);
    $('error-text').textContent = msg;
    $('error').hidden = false;
    changed(false);
  }
  $('error-close').onclick = () => { $('error').hidden = true; };

  /* fetch() with the token, answering an ApiError that carries the daemon's message for any
   * status but 2xx (the API's {"error": {"code", "message"}} body). */
  async function api(method, path, json) {
    const headers = {};
    if (state.token) headers.Authorization = 'Bearer ' + state.token;
    const init = { method, headers };
    if (json !== undefined) {
      headers['Content-Type'] = 'application/json';
      init.body = JSON.stringify(json);
    }
    let r;
    try {
      r = await fetch(path, init);
    } catch (e) {
      throw new ApiError(0, 'network',
        `${method} ${path}: no answer from fieldgripd (${e.message})`);
    }
    if (r.ok) return r;
    let code = 'http_' + r.status, msg = r.statusText || 'failed';
    try {
      const j = await r.json();
      if (j && j.error) { code = j.error.code; msg = j.error.message; }
    } catch (e) { /* not JSON: keep the status text */ }
    if (r.status === 401) askToken();
    throw new ApiError(r.status, code, `${method} ${path}: ${r.status} ${code}: ${msg}`);
  }

  const getJson = async (path) => (await api('GET', path)).json();
  const postJson = async (path, body) => (await api('POST', path, body)).json();

  /* Runs an action, counting it as busy and sending any error to the banner. Returns its
   * result, or undefined when it failed. */
  async function run(fn) {
    state.busy++;
    changed(false);
    try {
      return await fn();
    } catch (e) {
      if (!(e instanceof ApiError && e.status === 401)) showError(e);
      return undefined;
    } finally {
      state.busy--;
      changed(false);
    }
  }

  const enc = encodeURIComponent;
  const xyz = (p) => p.map((x) => x.toFixed(3)).join(', ');
  const scenePath = () => '/v1/scenes/' + enc(state.scene.name);

  /* ---------------------------------------------------------------- token */

  /* A 401: the daemon has a token and ours is missing or wrong. The page asks once; the
   * token stays in this tab (sessionStorage) or, when asked to, in this browser. */
  function askToken() {
    if (state.phase === 'need-token') return;
    state.phase = 'need-token';
    $('token-form').hidden = false;
    $('token-input').focus();
    changed(false);
  }

  $('token-form').onsubmit = (ev) => {
    ev.preventDefault();
    state.token = $('token-input').value.trim();
    sessionStorage.setItem(TOKEN_KEY, state.token);
    if ($('token-remember').checked) localStorage.setItem(TOKEN_KEY, state.token);
    else localStorage.removeItem(TOKEN_KEY);
    $('token-form').hidden = true;
    $('error').hidden = true;
    start();
  };

  /* ---------------------------------------------------------------- 3D view */

  /* The name of the browser's WebGL renderer, as a throwaway context reports it. */
  function glRendererName() {
    const gl = document.createElement('canvas').getContext('webgl');
    if (!gl) return '';
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    const lose = gl.getExtension('WEBGL_lose_context');
    if (lose) lose.loseContext();
    return name;
  }
  // Multisampling costs a renderer that draws on the CPU (SwiftShader, llvmpipe: a browser
  // without a GPU) half its frame rate on a large cloud; a GPU does it for little.
  const glName = glRendererName();
  const softwareGl = /swiftshader|llvmpipe|softpipe|software/i.test(glName);

  const canvas = $('canvas');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: !softwareGl });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0x1e1f24);
  const scene3 = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(DEFAULT_FOV_DEG, 1, 0.005, 50);
  camera.up.set(0, 0, 1); // the world's +z is up

  // The robot's base: axes (x red, y green, z blue) and a 2 m grid of 10 cm in the xy plane
  // (GridHelper lies in xz: turned a quarter about x).
  scene3.add(new THREE.AxesHelper(0.2));
  const grid = new THREE.GridHelper(2, 20, 0x555566, 0x33343c);
  grid.rotation.x = Math.PI / 2;
  scene3.add(grid);

  const groups = {
    workspace: new THREE.Group(),
    frustums: new THREE.Group(),
    demos: new THREE.Group(),
    grasps: new THREE.Group(),
    marker: new THREE.Group(),
  };
  for (const g of Object.values(groups)) scene3.add(g);
  let points = null; // the THREE.Points of the cloud

  function resize() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (w === 0 || h === 0) return;
    renderer.setSize(w, h, false);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    changed(true);
  }
  window.addEventListener('resize', resize);

  /* Orbit control: three's global build has no OrbitControls, and the camera must orbit
   * about +z (the world's up), so a small one here. Spherical coordinates about a target:
   * left drag turns (azimuth about z, elevation), right or shift drag pans in the view plane,
   * the wheel moves towards the target. */
  const orbit = { target: new THREE.Vector3(), dist: 1.5, az: -2.2, el: 0.6 };

  function orbitApply() {
    const c = Math.cos(orbit.el);
    camera.position.set(
      orbit.target.x + orbit.dist * c * Math.cos(orbit.az),
      orbit.target.y + orbit.dist * c * Math.sin(orbit.az),
      orbit.target.z + orbit.dist * Math.sin(orbit.el));
    camera.lookAt(orbit.target);
    camera.updateMatrixWorld();
    changed(true);
  }

  function orbitLookAt(eye, target) {
    orbit.target.copy(target);
    const d = new THREE.Vector3().subVectors(eye, target);
    orbit.dist = Math.max(d.length(), 1e-3);
    orbit.el = Math.asin(Math.max(-1, Math.min(1, d.z / orbit.dist)));
    orbit.az = Math.atan2(d.y, d.x);
    orbitApply();
  }

  let drag = null;
  canvas.addEventListener('contextmenu', (ev) => ev.preventDefault());
  canvas.addEventListener('pointerdown', (ev) => {
    drag = { x: ev.clientX, y: ev.clientY, pan: ev.button === 2 || ev.shiftKey, moved: 0 };
    canvas.setPointerCapture(ev.pointerId);
  });
  canvas.addEventListener('pointermove', (ev) => {
    if (!drag) return;
    const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
    drag.x = ev.clientX;
    drag.y = ev.clientY;
    drag.moved += Math.abs(dx) + Math.abs(dy);
    if (drag.pan) {
      // move the target in the view plane by as much as the pixels cover at its distance
      const scale = 2 * orbit.dist * Math.tan(camera.fov * Math.PI / 360) / canvas.clientHeight;
      const right = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 0);
      const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
      orbit.target.addScaledVector(right, -dx * scale).addScaledVector(up, dy * scale);
    } else {
      orbit.az -= dx * 0.008;
      orbit.el = Math.max(-1.55, Math.min(1.55, orbit.el + dy * 0.008));
    }
    orbitApply();
  });
  canvas.addEventListener('pointerup', (ev) => {
    if (drag && drag.moved < 4) pickFrustum(ev);
    drag = null;
  });
  canvas.addEventListener('wheel', (ev) => {
    ev.preventDefault();
    orbit.dist = Math.max(0.02, orbit.dist * Math.exp(ev.deltaY * 0.001));
    orbitApply();
  }, { passive: false });

  /* Draws only when something changed: a still scene costs nothing, and a turn of the view
   * redraws the one Points object (200k points) at the display's rate. */
  function frame() {
    if (state.drawnVersion !== state.version) {
      const drawing = state.version;
      renderer.render(scene3, camera);
      updateLabels();
      state.drawnVersion = drawing;
      if (state.loadedMs === null && state.cloud && points) state.loadedMs = performance.now();
      if (state.heatmapMs === null && state.heat) state.heatmapMs = performance.now();
      changed(false);
    }
    requestAnimationFrame(frame);
  }

  /* Each grasp's rank and score beside its TCP, as HTML over the canvas: text stays sharp
   * and costs no texture. Moved at every drawn frame, which only happens on a change. */
  function updateLabels() {
    const box = $('labels');
    while (box.children.length > state.grasps.length) box.lastChild.remove();
    const r = canvas.getBoundingClientRect();
    state.grasps.forEach((g, i) => {
      let el = box.children[i];
      if (!el) el = box.appendChild(document.createElement('div'));
      const p = project(g.pose.position);
      el.hidden = !p;
      if (!p) return;
      el.textContent = `${i + 1}: ${g.score.toFixed(3)}`;
      el.style.left = `${p.x - r.left}px`;
      el.style.top = `${p.y - r.top}px`;
      el.style.color = i === state.selectedGrasp ? '#ffd24a' : '';
    });
  }

  /* The page position (CSS pixels) of world point p, or null behind the camera. */
  function project(p) {
    const v = new THREE.Vector3(p[0], p[1], p[2]).project(camera);
    if (v.z > 1) return null;
    const r = canvas.getBoundingClientRect();
    return { x: r.left + (v.x + 1) / 2 * r.width, y: r.top + (1 - v.y) / 2 * r.height };
  }

  /* ---------------------------------------------------------------- geometry */

  const m4 = (rows) => new THREE.Matrix4().set(...rows[0], ...rows[1], ...rows[2], ...rows[3]);

  /* Places o by the row-major 4x4 matrix rows: applyMatrix in r111, applyMatrix4 from r115
   * on (where the old name warns), so that a newer libjs-three works too. */
  function place(o, rows) {
    if (o.applyMatrix4) o.applyMatrix4(m4(rows));
    else o.applyMatrix(m4(rows));
    return o;
  }

  /* Removes a group's children and frees their GPU buffers. */
  function empty(group) {
    for (const c of group.children.slice()) {
      group.remove(c);
      if (c.geometry) c.geometry.dispose();
      if (c.material) c.material.dispose();
    }
  }

  /* A LineSegments of the 12 edges of each box {centre, half_size} (in its own frame). */
  function boxesLines(boxes, color) {
    const pos = [];
    for (const b of boxes) {
      const c = b.centre, h = b.half_size;
      const corner = (i) => [c[0] + (i & 1 ? h[0] : -h[0]), c[1] + (i & 2 ? h[1] : -h[1]),
        c[2] + (i & 4 ? h[2] : -h[2])];
      for (let i = 0; i < 8; i++)
        for (const bit of [1, 2, 4])
          if (!(i & bit)) pos.push(...corner(i), ...corner(i | bit));
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
    return new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color }));
  }

  function drawWorkspace(ws) {
    empty(groups.workspace);
    const half = [0, 1, 2].map((a) => (ws.max[a] - ws.min[a]) / 2);
    const centre = [0, 1, 2].map((a) => (ws.max[a] + ws.min[a]) / 2);
    groups.workspace.add(boxesLines([{ centre, half_size: half }], 0x8899aa));
  }

  /* A frame's camera as a frustum 8 cm deep: the image's corners unprojected through its
   * intrinsics (OpenGL convention: the camera looks along its -z, image v grows down), plus a
   * triangle over the image's top edge to show which way is up. */
  function frustumLines(f, selected) {
    const c = f.camera, d = 0.08;
    const at = (u, v) => [(u - c.cx) / c.fl_x * d, -(v - c.cy) / c.fl_y * d, -d];
    const k = [at(0, 0), at(c.w, 0), at(c.w, c.h), at(0, c.h)];
    const top = at(c.w / 2, -0.25 * c.h);
    const pos = [];
    for (let i = 0; i < 4; i++) pos.push(0, 0, 0, ...k[i], ...k[i], ...k[(i + 1) % 4]);
    pos.push(...k[0], ...top, ...top, ...k[1]);
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(pos, 3));
    const colour = selected ? 0xffd24a : 0x5fa8d3;
    const l = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: colour }));
    place(l, f.transform_matrix);
    l.userData.frame = f.frame;
    return l;
  }

  function drawFrustums() {
    empty(groups.frustums);
    for (const f of state.frames) groups.frustums.add(frustumLines(f, f.frame === state.frame));
    changed(true);
  }

  /* A pose's axes (x red, y green, z blue: the approach) 5 cm long, for demos. */
  function poseAxes(pose, scale) {
    return place(new THREE.AxesHelper(scale), pose.matrix);
  }

  /* ---------------------------------------------------------------- point cloud */

  const { parseFgpc, parsePly } = window.fgFormats;

  async function loadPoints() {
    const alpha = Number($('alpha').value) || 0.1;
    const max = Math.floor(Number($('max-points').value)) || 200000;
    const r = await api('GET', `${scenePath()}/points?alpha=${alpha}&max_points=${max}`);
    const cloud = parseFgpc(await r.arrayBuffer());
    if (points) {
      scene3.remove(points);
      points.geometry.dispose();
      points.material.dispose();
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(cloud.xyz, 3));
    // one colour array, normalised bytes, rewritten in place by heatmaps
    g.setAttribute('color', new THREE.BufferAttribute(new Uint8Array(cloud.base), 3, true));
    if (cloud.count) g.computeBoundingSphere();
    else g.boundingSphere = new THREE.Sphere(); // three reports NaN radii of empty clouds
    // three's point size with sizeAttenuation is size * (viewport height / 2) / depth, which
    // is tan(fov / 2) times the projected size of an object as wide: divide it out so that a
    // point covers its voxel
    const size = cloud.voxel / Math.tan(camera.fov * Math.PI / 360);
    // THREE.VertexColors until r124, a boolean since
    const vertexColors = THREE.VertexColors !== undefined ? THREE.VertexColors : true;
    points = new THREE.Points(g, new THREE.PointsMaterial({ size, vertexColors }));
    scene3.add(points);
    state.cloud = cloud;
    state.heat = null;
    $('legend').hidden = true;
    empty(groups.marker);
    $('points-info').textContent = `${cloud.count} points` +
      (cloud.count < cloud.nSolid ? ` (of ${cloud.nSolid} solid voxels)` : '') +
      ` at ${(cloud.voxel * 100).toFixed(1)} cm, alpha >= ${+cloud.alpha.toPrecision(3)}`;
    changed(true);
  }

  /* ---------------------------------------------------------------- heatmaps */

  /* The query of the form (or a deep link): text or embedding, and negatives. */
  function formQuery() {
    const kind = $('query-kind').value, raw = $('query-input').value.trim();
    if (!raw) return null;
    const q = {};
    if (kind === 'embedding') {
      q.embedding = raw.split(/[\s,]+/).filter((s) => s).map(Number);
      if (q.embedding.some((x) => !isFinite(x)))
        throw new Error('the embedding must be numbers separated by commas: v1,v2,...');
    } else {
      q.text = raw;
    }
    const neg = $('negatives').value.split(',').map((s) => s.trim()).filter((s) => s);
    if (neg.length) q.negatives = neg;
    return q;
  }

  /* Scores the cloud's voxels for query q: POST .../heatmap as a PLY point list, whose
   * colours are the daemon's turbo map between the lowest and highest score listed (the
   * colour map has one home, lib/query), written over the colour of the cloud's point in the
   * same voxel. The list is best first: its first voxel is marked. */
  async function runHeatmap(q) {
    state.query = q;
    if (!state.cloud) return;
    const body = Object.assign({}, q, { format: 'ply', alpha_threshold: state.cloud.alpha });
    const r = await api('POST', `${scenePath()}/heatmap`, body);
    const list = parsePly(await r.arrayBuffer());
    const c = state.cloud, [nx, ny, nz] = c.n;
    const colours = points.geometry.attributes.color;
    // voxels that are not listed (none at the cloud's own alpha): the field's colour, dimmed
    for (let i = 0; i < 3 * c.count; i++) colours.array[i] = c.base[i] >> 2;
    let lo = Infinity, hi = -Infinity, scored = 0;
    for (let k = 0; k < list.count; k++) {
      const v = [0, 1, 2].map((a) => Math.floor((list.xyz[3 * k + a] - c.min[a]) / c.voxel));
      if (v[0] < 0 || v[1] < 0 || v[2] < 0 || v[0] >= nx || v[1] >= ny || v[2] >= nz) continue;
      const s = list.score[k];
      lo = Math.min(lo, s);
      hi = Math.max(hi, s);
      // the cloud is in flat-index order (FGPC): find the voxel's point by bisection
      const flat = (v[2] * ny + v[1]) * nx + v[0];
      let a = 0, b = c.count;
      while (a < b) {
        const m = (a + b) >> 1;
        if (c.index[m] < flat) a = m + 1; else b = m;
      }
      if (a === c.count || c.index[a] !== flat) continue; // thinned away
      colours.array.set(list.rgb.subarray(3 * k, 3 * k + 3), 3 * a);
      scored++;
    }
    colours.needsUpdate = true;
    empty(groups.marker);
    const heat = { lo, hi, scored, best: null, bestScore: null };
    if (list.count) {
      heat.best = Array.from(list.xyz.subarray(0, 3));
      heat.bestScore = list.score[0];
      // a white ring around the best voxel and a post up from it, visible through the cloud
      const ring = new THREE.Mesh(new THREE.RingGeometry(2.5 * c.voxel, 3.5 * c.voxel, 32),
        new THREE.MeshBasicMaterial({ color: 0xffffff, side: THREE.DoubleSide, depthTest: false }));
      ring.position.set(...heat.best);
      const post = new THREE.BufferGeometry();
      post.setAttribute('position', new THREE.Float32BufferAttribute([...heat.best,
        heat.best[0], heat.best[1], heat.best[2] + 0.12], 3));
      const line = new THREE.Line(post,
        new THREE.LineBasicMaterial({ color: 0xffffff, depthTest: false }));
      ring.renderOrder = line.renderOrder = 1;
      groups.marker.add(ring, line);
    }
    state.heat = heat;
    $('legend').hidden = false;
    $('legend-lo').textContent = isFinite(lo) ? lo.toFixed(3) : '-';
    $('legend-hi').textContent = isFinite(hi) ? hi.toFixed(3) : '-';
    $('query-info').textContent = heat.best
      ? `best ${xyz(heat.best)} m, score ${heat.bestScore.toFixed(3)}; ` +
        `${scored} of ${c.count} points scored`
      : 'no occupied voxel at this alpha';
    changed(true);
  }

  function clearHeatmap() {
    state.query = null;
    state.heat = null;
    $('legend').hidden = true;
    $('query-info').textContent = '';
    empty(groups.marker);
    if (points) {
      points.geometry.attributes.color.array.set(state.cloud.base);
      points.geometry.attributes.color.needsUpdate = true;
    }
    changed(true);
  }

  $('query-form').onsubmit = (ev) => {
    ev.preventDefault();
    run(async () => {
      const q = formQuery();
      if (!q) return clearHeatmap();
      if (!state.scene) throw new Error('open a scene first');
      if (!state.cloud) throw new Error(`scene '${state.scene.name}' has no trained field to ` +
        'query yet: train it first (Training, below)');
      await runHeatmap(q);
    });
  };
  $('query-clear').onclick = () => { $('query-input').value = ''; clearHeatmap(); };

  /* ---------------------------------------------------------------- frames */

  function pickFrustum(ev) {
    const r = canvas.getBoundingClientRect();
    const ndc = new THREE.Vector2((ev.clientX - r.left) / r.width * 2 - 1,
      -(ev.clientY - r.top) / r.height * 2 + 1);
    const ray = new THREE.Raycaster();
    // a few pixels, whatever the zoom: linePrecision in r111, params.Line.threshold later
    const near = 0.004 * orbit.dist;
    if (ray.params.Line && 'threshold' in ray.params.Line) ray.params.Line.threshold = near;
    else ray.linePrecision = near;
    ray.setFromCamera(ndc, camera);
    const hit = ray.intersectObjects(groups.frustums.children)[0];
    if (hit) selectFrame(hit.object.userData.frame);
  }

  const objectUrls = {};
  function showImage(img, blob) {
    if (objectUrls[img.id]) URL.revokeObjectURL(objectUrls[img.id]);
    objectUrls[img.id] = URL.createObjectURL(blob);
    return new Promise((resolve, reject) => {
      img.onload = resolve;
      img.onerror = () => reject(new Error(`the ${img.alt} did not decode`));
      img.src = objectUrls[img.id];
    });
  }

  /* The frame's photo beside the field rendered from the same camera. */
  function selectFrame(number) {
    const f = state.frames.find((x) => x.frame === number);
    if (!f) return Promise.resolve(showError(`no frame ${number}`));
    state.frame = number;
    drawFrustums();
    $('frame-view').hidden = false;
    $('frame-title').textContent = `frame ${number}: ${f.source} (${f.camera.w}x${f.camera.h})`;
    const c = f.camera;
    const photo = run(async () => {
      const r = await api('GET', `${scenePath()}/frames/${number}/image`);
      await showImage($('frame-photo'), await r.blob());
    });
    const render = run(async () => {
      $('frame-render').removeAttribute('src');
      if (!state.scene.trained) throw new Error(`scene '${state.scene.name}' is not trained: ` +
        'no field to render');
      const r = await api('POST', `${scenePath()}/render`, {
        camera: { transform_matrix: f.transform_matrix, fl_x: c.fl_x, fl_y: c.fl_y, cx: c.cx,
          cy: c.cy, w: c.w, h: c.h }, output: 'rgb' });
      await showImage($('frame-render'), await r.blob());
    });
    return Promise.all([photo, render]);
  }
  $('frame-close').onclick = () => {
    $('frame-view').hidden = true;
    state.frame = -1;
    drawFrustums();
  };

  /* ---------------------------------------------------------------- tasks and grasps */

  async function loadTasks() {
    state.tasks = (await getJson('/v1/tasks')).tasks;
    const sel = $('task-select'), keep = sel.value;
    sel.length = 1;
    for (const t of state.tasks) {
      const o = document.createElement('option');
      o.value = t.name;
      o.textContent = `${t.name} (${t.kind || 'empty'}, ${t.n_demos} demos)`;
      sel.appendChild(o);
    }
    sel.value = state.tasks.some((t) => t.name === keep) ? keep : '';
  }

  /* The task's demos on this scene as pose axes. */
  async function selectTask(name) {
    // a task made since the page loaded (by a script, another client): list it first
    if (name && !state.tasks.some((t) => t.name === name)) await loadTasks();
    $('task-select').value = name;
    empty(groups.demos);
    $('task-info').textContent = '';
    if (name) {
      const t = await getJson('/v1/tasks/' + enc(name));
      const here = (t.demos || []).filter((d) => state.scene && d.scene === state.scene.name);
      for (const d of here) groups.demos.add(poseAxes(d.pose, 0.05));
      $('task-info').textContent = `${t.kind || 'no'} task, ${t.n_demos} demos (${here.length} ` +
        `on this scene, drawn as axes: z is the approach)` +
        (t.width ? `, width ${(t.width * 100).toFixed(1)} cm` : '');
    }
    changed(true);
  }
  $('task-select').onchange = () => run(() => selectTask($('task-select').value));

  /* POST .../grasps with the task, else the query (which retrieves the task). */
  async function findGrasps() {
    if (!state.scene) throw new Error('open a scene first');
    const body = { top_k: Math.max(1, Math.min(100, Math.floor(Number($('top-k').value)) || 5)) };
    const task = $('task-select').value;
    if (task) body.task = task;
    else if (state.query) Object.assign(body, state.query);
    else throw new Error('choose a task, or run a query first: grasps need one of them');
    const res = await postJson(`${scenePath()}/grasps`, body);
    state.grasps = res.grasps;
    state.gripper = res.gripper;
    state.selectedGrasp = res.grasps.length ? 0 : -1;
    const list = $('grasp-list');
    list.textContent = '';
    res.grasps.forEach((g, i) => {
      const li = document.createElement('li');
      li.textContent = `${g.score.toFixed(3)} ${g.task} at ${xyz(g.pose.position)}` +
        (g.collision_free ? '' : ' (collides)');
      li.onclick = () => selectGrasp(i);
      list.appendChild(li);
    });
    $('task-info').textContent = !res.grasps.length ? `no grasp: ${res.reason}`
      : `task ${res.task}: ${res.grasps.length} grasps` +
        (res.retrieval ? ' (retrieved by the query)' : '');
    $('grasp-actions').hidden = !res.grasps.length;
    $('registers').textContent = '';
    drawGrasps();
  }
  $('find-grasps').onclick = () => run(findGrasps);

  /* Each grasp as the gripper's boxes at its pose, the selected one yellow, the others green
   * fading with rank, plus a line from its pre-grasp pose; its score as a label. */
  function drawGrasps() {
    empty(groups.grasps);
    if (!state.gripper || !state.gripper.boxes) return changed(true);
    state.grasps.forEach((g, i) => {
      const sel = i === state.selectedGrasp;
      const fade = 1 - 0.6 * i / Math.max(1, state.grasps.length);
      const colour = sel ? 0xffd24a : new THREE.Color(0.25 * fade, 0.9 * fade, 0.45 * fade);
      const lines = place(boxesLines(state.gripper.boxes, colour), g.pose.matrix);
      const approach = new THREE.BufferGeometry();
      approach.setAttribute('position', new THREE.Float32BufferAttribute(
        [...g.pre_grasp.position, ...g.pose.position], 3));
      const line = new THREE.Line(approach, new THREE.LineBasicMaterial({ color: colour }));
      groups.grasps.add(lines, line);
    });
    [...$('grasp-list').children].forEach((li, i) =>
      li.classList.toggle('selected', i === state.selectedGrasp));
    changed(true);
  }

  function selectGrasp(i) {
    state.selectedGrasp = i;
    $('execute-confirm').hidden = true;
    $('registers').textContent = '';
    drawGrasps();
  }

  /* The register words a command writes (proto/modbus.md), as the dry run reports them. */
  function registersText(cmd) {
    const lines = [];
    const reg = cmd.registers || {};
    if (reg.robot)
      lines.push(`robot unit ${reg.robot.unit_id} @${reg.robot.address} (${reg.robot.encoding}): ` +
        reg.robot.words.join(' '));
    for (const s of reg.gripper || [])
      lines.push(`${s.step} unit ${s.unit_id} @${s.address}: ${s.words.join(' ')}`);
    return lines.join('\n') || JSON.stringify(cmd);
  }

  async function execute(dryRun) {
    const g = state.grasps[state.selectedGrasp];
    if (!g) throw new Error('select a grasp first');
    $('registers').textContent = dryRun ? 'dry run...' : 'moving the robot...';
    const cmd = await postJson(`${scenePath()}/grasps/${enc(g.id)}/execute`,
      { dry_run: dryRun, wait: !dryRun });
    $('registers').textContent = (dryRun ? 'dry run (nothing sent), seq ' + cmd.seq + ':\n'
      : `command ${cmd.id}: ${cmd.state}\n`) + registersText(cmd);
    state.lastCommand = cmd;
    changed(false);
  }
  $('dry-run').onclick = () => run(() => execute(true));
  $('execute').onclick = () => {
    const g = state.grasps[state.selectedGrasp];
    if (!g) return showError('select a grasp first');
    $('execute-question').textContent = `Move the robot to ${g.kind} at ` +
      `${xyz(g.pose.position)} (task ${g.task})?`;
    $('execute-confirm').hidden = false;
  };
  $('execute-no').onclick = () => { $('execute-confirm').hidden = true; };
  $('execute-yes').onclick = () => {
    $('execute-confirm').hidden = true;
    run(() => execute(false));
  };

  /* ---------------------------------------------------------------- training */

  const plot = { steps: [], loss: [], psnr: [] };

  function drawPlot() {
    const cv = $('train-plot'), cx = cv.getContext('2d'), w = cv.width, h = cv.height;
    cx.clearRect(0, 0, w, h);
    const n = plot.steps.length;
    if (n < 1) return;
    const maxStep = Math.max(1, state.job ? state.job.steps : plot.steps[n - 1]);
    const series = (values, colour, label, y0) => {
      const v = values.filter((x) => typeof x === 'number' && isFinite(x));
      if (!v.length) return;
      const lo = Math.min(...v), hi = Math.max(...v), span = hi > lo ? hi - lo : 1;
      cx.strokeStyle = colour;
      cx.beginPath();
      let started = false;
      for (let i = 0; i < n; i++) {
        const x = values[i];
        if (!(typeof x === 'number' && isFinite(x))) continue;
        const px = plot.steps[i] / maxStep * (w - 4) + 2, py = h - 4 - (x - lo) / span * (h - 20);
        if (started) cx.lineTo(px, py); else cx.moveTo(px, py);
        started = true;
      }
      cx.stroke();
      cx.fillStyle = colour;
      cx.fillText(`${label} ${v[v.length - 1].toFixed(label === 'loss' ? 4 : 2)}`, y0, 11);
    };
    cx.font = '10px sans-serif';
    // the loss on a log scale: it falls over orders of magnitude
    series(plot.loss.map((x) => (x > 0 ? Math.log10(x) : NaN)), '#f0a050', 'log10 loss', 4);
    series(plot.psnr, '#60c0f0', 'PSNR dB', 150);
  }

  /* Follows a job's Server-Sent Events (GET /v1/jobs/{id}/events) until its final event.
   * fetch() with a streaming reader, not EventSource: EventSource cannot send the
   * Authorization header, and one code path serves both kinds of daemon. */
  async function followJob(id) {
    plot.steps.length = plot.loss.length = plot.psnr.length = 0;
    $('train-cancel').disabled = false;
    $('train-cancel').onclick = () => run(() => api('DELETE', '/v1/jobs/' + enc(id)));
    const r = await api('GET', `/v1/jobs/${enc(id)}/events`);
    const reader = r.body.getReader(), dec = new TextDecoder();
    let buf = '', final = null;
    while (!final) {
      const { value, done } = await reader.read();
      if (done) break;
      buf += dec.decode(value, { stream: true });
      let cut;
      while ((cut = buf.indexOf('\n\n')) >= 0) {
        const block = buf.slice(0, cut);
        buf = buf.slice(cut + 2);
        let name = 'message', data = '';
        for (const line of block.split('\n')) {
          if (line.startsWith('event:')) name = line.slice(6).trim();
          else if (line.startsWith('data:')) data += line.slice(5).trim();
        }
        if (!data) continue; // a keep-alive comment
        onJobEvent(name, JSON.parse(data));
        if (name !== 'progress') final = name;
      }
    }
    $('train-cancel').disabled = true;
    if (!final) throw new Error(`job ${id}: its event stream ended before the job did`);
    if (final === 'failed') throw new Error(`training job ${id} failed: ${state.job.error}`);
    if (final === 'done') await reopenScene();
  }

  function onJobEvent(name, job) {
    state.job = job;
    state.progressEvents++;
    if (plot.steps[plot.steps.length - 1] !== job.step) {
      plot.steps.push(job.step);
      plot.loss.push(job.loss);
      plot.psnr.push(job.psnr);
    }
    $('train-progress').value = job.steps ? job.step / job.steps : 0;
    $('train-info').textContent = `job ${job.id}: ${job.state}, step ${job.step} of ${job.steps}` +
      (typeof job.eta_s === 'number' && job.state === 'running'
        ? `, ${Math.round(job.eta_s)} s left` : '');
    drawPlot();
    changed(false);
  }

  /* The scene's field settings in their selects (a value set through the API that the list
   * lacks gets an option); a scene of the configuration file keeps the file's. */
  function showFieldSettings(s) {
    const scale = $('field-scale'), bg = $('learn-background');
    const v = String(s.field_scale);
    if (![...scale.options].some((o) => o.value === v)) scale.add(new Option(v, v));
    scale.value = v;
    bg.value = String(s.learn_background);
    for (const el of [scale, bg]) {
      el.disabled = s.declared_in_config;
      el.title = s.declared_in_config ? 'set in the configuration file\'s [scene] section' : '';
    }
  }

  async function patchFieldSettings(body) {
    const r = await api('PATCH', scenePath(), body);
    state.scene = await r.json();
    showFieldSettings(state.scene);
  }

  $('field-scale').onchange = (e) => run(() => patchFieldSettings({
    field_scale: e.target.value === 'auto' ? 'auto' : Number(e.target.value) }))
    .then(() => showFieldSettings(state.scene));
  $('learn-background').onchange = (e) => run(() => patchFieldSettings({
    learn_background: e.target.value === 'auto' ? 'auto' : e.target.value === 'true' }))
    .then(() => showFieldSettings(state.scene));

  $('train').onclick = () => run(async () => {
    if (!state.scene) throw new Error('open a scene first');
    const steps = Math.floor(Number($('train-steps').value));
    const res = await postJson(`${scenePath()}/train`, steps > 0 ? { steps } : {});
    await followJob(res.job);
  });

  /* ---------------------------------------------------------------- scenes */

  /* The view of the workspace from the front left, above, or the deep link's eye and target. */
  function defaultView(ws) {
    const vec = (s) => s && s.split(',').map(Number).length === 3 ? s.split(',').map(Number) : null;
    const centre = [0, 1, 2].map((a) => (ws.min[a] + ws.max[a]) / 2);
    const size = Math.max(...[0, 1, 2].map((a) => ws.max[a] - ws.min[a]));
    const eye = vec(link.get('eye')) ||
      [centre[0] - 0.9 * size, centre[1] - 1.1 * size, centre[2] + 1.0 * size];
    const target = vec(link.get('target')) || centre;
    const fov = Number(link.get('fov'));
    camera.fov = fov > 1 && fov < 170 ? fov : DEFAULT_FOV_DEG;
    camera.updateProjectionMatrix();
    orbitLookAt(new THREE.Vector3(...eye), new THREE.Vector3(...target));
  }

  /* Describes the scene and shows what exists of it: frames always, the point cloud and the
   * query once it is trained. */
  async function openScene(name, first) {
    state.scene = await getJson('/v1/scenes/' + enc(name));
    state.frames = (await getJson(`${scenePath()}/frames`)).frames;
    $('scene-select').value = name;
    drawWorkspace(state.scene.workspace);
    if (first) defaultView(state.scene.workspace);
    drawFrustums();
    const s = state.scene;
    $('scene-info').textContent = `${s.frames} frames, ` + (s.trained
      ? `trained ${s.trained_steps} steps` : 'not trained yet: train it below') +
      (s.feature_dim ? `, features D = ${s.feature_dim}` : ', no features') +
      (s.field ? `, field ${+s.field.scale.toFixed(3)} \u00d7 the workspace` +
        (s.field.learn_background ? ' with a learned background' : '') : '');
    showFieldSettings(s);
    if (s.trained) {
      await loadPoints();
      if (state.query) await runHeatmap(state.query);
    } else if (points) {
      scene3.remove(points);
      points.geometry.dispose();
      points.material.dispose();
      points = null;
      state.cloud = null;
    }
    const job = s.last_job;
    if (job && (job.state === 'queued' || job.state === 'running')) run(() => followJob(job.id));
  }

  /* After a training: the new field's points, the query again. */
  const reopenScene = () => openScene(state.scene.name, false);

  $('scene-select').onchange = () => run(async () => {
    clearHeatmap();
    state.grasps = [];
    drawGrasps();
    await openScene($('scene-select').value, true);
    await selectTask($('task-select').value);
  });
  $('points-reload').onclick = () => run(async () => {
    await loadPoints();
    if (state.query) await runHeatmap(state.query);
  });

  /* Loads everything the deep link names: the scene, the query, the task (whose grasps are
   * then found). A 401 stops it here; the token form starts it again. */
  async function start() {
    state.phase = 'loading';
    changed(false);
    await run(async () => {
      const health = await getJson('/v1/health');
      $('version').textContent = health.version;
      const scenes = (await getJson('/v1/scenes')).scenes;
      const sel = $('scene-select');
      sel.length = 0;
      for (const s of scenes) {
        const o = document.createElement('option');
        o.value = o.textContent = s.name;
        sel.appendChild(o);
      }
      await loadTasks();
      const name = link.get('scene') || (scenes[0] && scenes[0].name);
      if (!name) throw new Error('fieldgripd has no scene yet: POST /v1/scenes creates one');
      if (link.get('text')) {
        $('query-kind').value = 'text';
        $('query-input').value = link.get('text');
      } else if (link.get('embedding')) {
        $('query-kind').value = 'embedding';
        $('query-input').value = link.get('embedding');
      }
      if (link.get('negatives')) $('negatives').value = link.get('negatives');
      if (link.get('alpha')) $('alpha').value = link.get('alpha');
      state.query = formQuery();
      await openScene(name, true);
      if (link.get('task')) {
        await selectTask(link.get('task'));
        if (state.scene.trained) await findGrasps();
      }
    });
    if (state.phase === 'loading') state.phase = 'ready';
    changed(false);
  }

  /* ---------------------------------------------------------------- for tests and scripts */

  function status() {
    const r = canvas.getBoundingClientRect();
    return {
      phase: state.phase, busy: state.busy, errors: state.errors.slice(),
      banner: $('error').hidden ? null : $('error-text').textContent,
      scene: state.scene && state.scene.name, trained: !!(state.scene && state.scene.trained),
      frames: state.frames.length, frame: state.frame,
      photo: $('frame-photo').naturalWidth, render: $('frame-render').naturalWidth,
      points: state.cloud ? state.cloud.count : 0, solid: state.cloud ? state.cloud.nSolid : 0,
      heatmap: !!state.heat, best: state.heat && state.heat.best,
      bestScore: state.heat && state.heat.bestScore,
      grasps: state.grasps.length, gripper: state.gripper && state.gripper.model,
      selectedGrasp: state.selectedGrasp >= 0
        ? state.grasps[state.selectedGrasp].pose.position : null,
      registers: $('registers').textContent,
      job: state.job && { id: state.job.id, state: state.job.state, step: state.job.step,
        steps: state.job.steps },
      progressEvents: state.progressEvents,
      drawn: state.drawnVersion === state.version, loadedMs: state.loadedMs,
      heatmapMs: state.heatmapMs,
      gl: glName, antialias: !softwareGl,
      canvas: { left: r.left, top: r.top, width: r.width, height: r.height },
      camera: { position: camera.position.toArray(), target: orbit.target.toArray(),
        fov: camera.fov, aspect: camera.aspect },
    };
  }

  window.fgViewer = {
    status,
    project,
    selectFrame: (i) => selectFrame(i).then(status),
    selectTask: (name) => run(() => selectTask(name)).then(status),
    findGrasps: () => run(findGrasps).then(status),
    selectGrasp: (i) => { selectGrasp(i); return status(); },
    dryRun: () => run(() => execute(true)).then(status),
    /* Turns the view once around in n drawn frames and resolves with the mean time per
     * frame (ms) and the points drawn: how fast this machine draws the cloud. */
    benchmark(n) {
      n = n || 60;
      return new Promise((resolve) => {
        let k = 0, t0 = 0;
        const step = (t) => {
          if (k === 1) t0 = t; // the first frame's timestamp starts the clock
          if (k === n + 1) {
            const count = state.cloud ? state.cloud.count : 0;
            resolve({ frames: n, msPerFrame: (t - t0) / n, points: count });
            return;
          }
          orbit.az += 2 * Math.PI / n;
          orbitApply();
          k++;
          requestAnimationFrame(step);
        };
        requestAnimationFrame(step);
      });
    },
    /* Resolves with status() once pred() holds (checked at every change, not polled);
     * rejects with the status after timeoutMs. */
    waitFor(pred, timeoutMs) {
      return new Promise((resolve, reject) => {
        const w = { pred, resolve };
        w.timer = setTimeout(() => {
          waiters.splice(waiters.indexOf(w), 1);
          reject(new Error('timed out waiting; status: ' + JSON.stringify(status())));
        }, timeoutMs || 60000);
        waiters.push(w);
        changed(false);
      });
    },
  };

  resize();
  new ResizeObserver(resize).observe(canvas);
  requestAnimationFrame(frame);
  start();
})();
