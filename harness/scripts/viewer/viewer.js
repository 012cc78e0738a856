// deformbench viewer: every run of a results folder side by side under one camera, over the
// surface series, coloured by the distance to the reference. Data: the JSON in #dbv-data
// (viewer_data.py describes the encoding). URL hash: frame=K|last (the frame shown), run=A,B
// (show only these labels, separated by |, and the reference), play=1.
/* global THREE */
(function () {
  'use strict';
  const root = document.getElementById('dbv');
  const errors = [];
  function fail(msg) {
    errors.push(msg);
    const box = root.querySelector('.dbv-errors');
    if (box) box.textContent = errors.join('\n');
    document.body.setAttribute('data-viewer-errors', String(errors.length));
    document.body.setAttribute('data-viewer-status', 'error');
  }
  window.addEventListener('error', (e) => fail('error: ' + e.message));
  window.addEventListener('unhandledrejection', (e) => fail('error: ' + (e.reason && e.reason.message || e.reason)));

  const VIRIDIS = [[0x44, 0x01, 0x54], [0x47, 0x2c, 0x7a], [0x3b, 0x51, 0x8b], [0x2c, 0x71, 0x8e],
    [0x21, 0x90, 0x8d], [0x27, 0xad, 0x81], [0x5c, 0xc8, 0x63], [0xaa, 0xdc, 0x32], [0xfd, 0xe7, 0x25]];
  const OVER = [1.0, 0.0, 1.0];   // beyond a clipped colour range: magenta, named on the bar
  const NEUTRAL = [0.86, 0.74, 0.64];  // the reference, and models where no reference surface exists
  function viridis(x, out, o) {
    const s = Math.min(Math.max(x, 0), 1) * (VIRIDIS.length - 1);
    const i = Math.min(Math.floor(s), VIRIDIS.length - 2), f = s - i;
    for (let k = 0; k < 3; ++k) out[o + k] = ((1 - f) * VIRIDIS[i][k] + f * VIRIDIS[i + 1][k]) / 255;
  }

  function bytes(b64) {
    const s = atob(b64);
    const u = new Uint8Array(s.length);
    for (let i = 0; i < s.length; ++i) u[i] = s.charCodeAt(i);
    return u;
  }
  async function inflate(b64) {
    const stream = new Blob([bytes(b64)]).stream().pipeThrough(new DecompressionStream('deflate'));
    return new Uint8Array(await new Response(stream).arrayBuffer());
  }
  async function floats(b64) {
    const u = await inflate(b64);
    return new Float32Array(u.buffer, u.byteOffset, u.byteLength / 4);
  }
  function fmtMm(m) { return m == null ? '-' : (1e3 * m).toPrecision(3) + ' mm'; }
  function esc(s) {
    return String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' }[c]));
  }
  function hashParams() {
    const out = {};
    for (const part of location.hash.replace(/^#/, '').split('&')) {
      const eq = part.indexOf('=');
      if (eq > 0) out[decodeURIComponent(part.slice(0, eq))] = decodeURIComponent(part.slice(eq + 1));
    }
    return out;
  }

  // A run's decoded series: quantised frames, undone lazily into float positions.
  class Series {
    constructor(run, n, q, base) {
      this.run = run; this.n = n; this.q = q; this.base = base;
      this.cacheFrame = -1; this.pos = new Float32Array(3 * n);
    }
    // Positions (x y z interleaved) of local frame f.
    at(f) {
      if (f === this.cacheFrame) return this.pos;
      const n = this.n, q = this.q, s = this.run.scale, b = this.base, S = 3 * n, o = f * S;
      for (let i = 0; i < n; ++i) {
        this.pos[3 * i] = b[3 * i] + s[0] * q[o + i];
        this.pos[3 * i + 1] = b[3 * i + 1] + s[1] * q[o + n + i];
        this.pos[3 * i + 2] = b[3 * i + 2] + s[2] * q[o + 2 * n + i];
      }
      this.cacheFrame = f;
      return this.pos;
    }
  }
  async function decodeRun(run, n, rest) {
    const raw = await inflate(run.data);
    const N = raw.length / 2, lo = raw.subarray(0, N), hi = raw.subarray(N);
    const q = new Int16Array(N);
    for (let i = 0; i < N; ++i) q[i] = lo[i] | (hi[i] << 8);
    const S = 3 * n;
    for (let k = S; k < N; ++k) q[k] = q[k] + q[k - S];  // Int16Array wraps as the encoder did
    const base = run.base ? await floats(run.base) : rest;
    return new Series(run, n, q, base);
  }
  // Index of the local frame shown at global time t: the last one at or before t (else the first).
  function localFrame(run, t) {
    let best = 0;
    for (let i = 0; i < run.times.length; ++i) if (run.times[i] <= t + 1e-12) best = i;
    return best;
  }
  function lerpTool(tool, t) {
    const tr = tool.trajectory;
    if (!tr.length) return null;
    if (t <= tr[0].t) return { pos: tr[0].pos, jaw: tr[0].jaw };
    for (let i = 0; i + 1 < tr.length; ++i) {
      if (t <= tr[i + 1].t) {
        const f = (t - tr[i].t) / (tr[i + 1].t - tr[i].t);
        return { pos: [0, 1, 2].map((k) => (1 - f) * tr[i].pos[k] + f * tr[i + 1].pos[k]), jaw: tr[i].jaw };
      }
    }
    const last = tr[tr.length - 1];
    return { pos: last.pos, jaw: last.jaw };
  }

  async function main() {
    const D = JSON.parse(document.getElementById('dbv-data').textContent);
    const hp = hashParams();
    root.innerHTML =
      '<div class="dbv-bar1"><button class="dbv-play">play</button>' +
      '<input class="dbv-slider" type="range" min="0" value="0" step="1">' +
      '<span class="dbv-time"></span><button class="dbv-reset">reset view</button></div>' +
      '<div class="dbv-stage"><canvas></canvas></div>' +
      '<div class="dbv-bar2"><span class="dbv-legend"></span>' +
      '<label>colour max (mm) <input class="dbv-max" type="number" min="0" step="any" style="width:7em"></label>' +
      '<button class="dbv-truemax">full range</button>' +
      '<label>scale <select class="dbv-scale"><option value="shared">shared by every panel</option>' +
      '<option value="panel">each panel its own</option></select></label></div>' +
      '<div class="dbv-keys">Drag: orbit; right-drag or shift-drag: pan; wheel: zoom. ' +
      'Red points: grasped surface vertices; dark points: fixed surface vertices; boxes: fixed region; red line: tool path; sphere: tool (red: jaws closed).</div>' +
      '<div class="dbv-status">loading...</div><div class="dbv-errors"></div>';
    const status = root.querySelector('.dbv-status');
    const n = D.n;
    const faces = await inflate(D.faces);
    const index = new Uint32Array(faces.buffer, faces.byteOffset, faces.byteLength / 4);
    const rest = D.rest ? await floats(D.rest) : null;
    const series = [];
    for (const r of D.runs) series.push(await decodeRun(r, n, rest));
    const refIndex = D.reference;
    let shown = D.runs.map((_, i) => i);
    if (hp.run) {
      const want = hp.run.split('|');
      const sel = shown.filter((i) => want.includes(D.runs[i].label) || i === refIndex);
      if (sel.length) shown = sel;
    }
    // Models first, the reference last.
    shown.sort((a, b) => (a === refIndex) - (b === refIndex) || a - b);

    // Bounds of every frame of every shown run (the camera frames them all).
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (const i of shown) {
      for (let f = 0; f < D.runs[i].times.length; ++f) {
        const p = series[i].at(f);
        for (let v = 0; v < n; ++v) {
          for (let k = 0; k < 3; ++k) {
            const x = p[3 * v + k];
            if (x < lo[k]) lo[k] = x;
            if (x > hi[k]) hi[k] = x;
          }
        }
      }
    }
    const centre = new THREE.Vector3((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, (lo[2] + hi[2]) / 2);
    const size = Math.max(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) || 1;

    // Where the scene acts on the organ: the grasped vertices, else the tools' first positions,
    // else the loads' points (the home view looks at the organ from that side).
    const it0 = D.interaction || {};
    const acts = [];
    if (shown.length && (it0.grasped_vertices || []).length) {
      const x0 = series[shown[0]].at(0);
      for (const v of it0.grasped_vertices) acts.push([x0[3 * v], x0[3 * v + 1], x0[3 * v + 2]]);
    }
    if (!acts.length) for (const t of it0.tools || []) if (t.trajectory && t.trajectory.length) acts.push(t.trajectory[0].pos);
    if (!acts.length) for (const l of it0.loads || []) if (l.at) acts.push(l.at);
    const canvas = root.querySelector('canvas');
    const stage = root.querySelector('.dbv-stage');
    const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    const camera = new THREE.PerspectiveCamera(30, 1, size / 100, size * 100);
    camera.up.set(0, 0, 1);
    const dir = new THREE.Vector3(0.35, 1.0, 0.55).normalize();
    if (acts.length) {
      const a = new THREE.Vector3();
      for (const q of acts) a.add(new THREE.Vector3(q[0], q[1], q[2]));
      a.multiplyScalar(1 / acts.length).sub(centre);
      a.z = 0;  // look from the interaction's side, from above (z is up)
      if (a.length() > 0.05 * size) dir.copy(a.normalize()).add(new THREE.Vector3(0, 0, 0.6)).normalize();
    }
    camera.position.copy(centre).addScaledVector(dir, size * 2.7);
    const controls = new THREE.OrbitControls(camera, canvas);
    controls.target.copy(centre);
    controls.screenSpacePanning = true;
    // The home view frames the organ in a panel of the given aspect (width / height).
    function home(aspect) {
      const dist = 0.62 * size / Math.tan(camera.fov * Math.PI / 360) / Math.min(1, aspect);
      camera.position.copy(centre).addScaledVector(dir, dist);
      controls.target.copy(centre);
      controls.update();
      controls.saveState();
    }

    const it = D.interaction || { tools: [], loads: [], boxes: [], fixed_vertices: [], grasped_vertices: [] };
    const panels = shown.map((i) => {
      const run = D.runs[i];
      const scene = new THREE.Scene();
      scene.background = new THREE.Color(0xf4f4f4);
      scene.add(new THREE.HemisphereLight(0xffffff, 0x666666, 0.55));
      const light = new THREE.DirectionalLight(0xffffff, 0.6);
      scene.add(light);
      scene.add(light.target);
      const geom = new THREE.BufferGeometry();
      const pos = new THREE.BufferAttribute(new Float32Array(3 * n), 3);
      const col = new THREE.BufferAttribute(new Float32Array(3 * n), 3);
      geom.setAttribute('position', pos);
      geom.setAttribute('color', col);
      geom.setIndex(new THREE.BufferAttribute(index, 1));
      const mat = new THREE.MeshLambertMaterial({ vertexColors: THREE.VertexColors, side: THREE.DoubleSide });
      scene.add(new THREE.Mesh(geom, mat));
      const pts = (idx, colour, px) => {
        const g = new THREE.BufferGeometry();
        const a = new THREE.BufferAttribute(new Float32Array(3 * idx.length), 3);
        g.setAttribute('position', a);
        const p = new THREE.Points(g, new THREE.PointsMaterial({ color: colour, size: px, sizeAttenuation: false }));
        scene.add(p);
        return { idx, a, g };
      };
      const fixedPts = pts(it.fixed_vertices, 0x303030, 2);
      const graspPts = pts(it.grasped_vertices, 0xd01010, 4);
      for (const b of it.boxes) {
        const bg = new THREE.BoxBufferGeometry(b[1][0] - b[0][0], b[1][1] - b[0][1], b[1][2] - b[0][2]);
        const box = new THREE.LineSegments(new THREE.EdgesGeometry(bg), new THREE.LineBasicMaterial({ color: 0x555555 }));
        box.position.set((b[0][0] + b[1][0]) / 2, (b[0][1] + b[1][1]) / 2, (b[0][2] + b[1][2]) / 2);
        scene.add(box);
      }
      const tools = it.tools.map((t) => {
        const path = new THREE.BufferGeometry().setFromPoints(t.trajectory.map((k) => new THREE.Vector3(k.pos[0], k.pos[1], k.pos[2])));
        scene.add(new THREE.Line(path, new THREE.LineBasicMaterial({ color: 0xc03000 })));
        const m = new THREE.Mesh(new THREE.SphereBufferGeometry(Math.max(t.radius, size / 200), 16, 12),
          new THREE.MeshBasicMaterial({ color: 0xc03000, transparent: true, opacity: 0.3, depthWrite: false }));
        scene.add(m);
        return { t, m };
      });
      for (const l of it.loads) {
        const at = new THREE.Vector3(l.at[0], l.at[1], l.at[2]);
        const f = l.force ? new THREE.Vector3(l.force[0], l.force[1], l.force[2]) : new THREE.Vector3(0, 0, 1);
        if (f.length() > 0) scene.add(new THREE.ArrowHelper(f.clone().normalize(), at, size * 0.15, 0x0050c0));
      }
      const label = document.createElement('div');
      label.className = 'dbv-label';
      stage.appendChild(label);
      return { i, run, scene, light, geom, pos, col, fixedPts, graspPts, tools, label, rect: null };
    });

    const slider = root.querySelector('.dbv-slider');
    const timeText = root.querySelector('.dbv-time');
    const maxInput = root.querySelector('.dbv-max');
    const legend = root.querySelector('.dbv-legend');
    slider.max = String(D.times.length - 1);
    const trueMax = D.colour.true_max_m, fullMax = D.colour.max_m;
    let colourMax = fullMax > 0 ? fullMax : 1e-3;
    // Each run's largest distance over its frames: its panel's own scale.
    const panelMax = (i) => Math.max(0, ...(D.runs[i].frame_max_m || []).filter((v) => v != null));
    const scaleSelect = root.querySelector('.dbv-scale');
    // Per panel by default when one model's error dwarfs the others' (the good ones would all look
    // dark on a shared scale); #scale=shared or #scale=panel chooses.
    const maxes = shown.filter((i) => i !== refIndex).map(panelMax).filter((v) => v > 0).sort((a, b) => a - b);
    let perPanel = maxes.length > 1 && maxes[maxes.length - 1] > 3 * maxes[Math.floor((maxes.length - 1) / 2)];
    if (hp.scale === 'shared' || hp.scale === 'panel') perPanel = hp.scale === 'panel';
    scaleSelect.value = perPanel ? 'panel' : 'shared';
    maxInput.value = (1e3 * colourMax).toPrecision(4);
    let frame = D.times.length - 1;
    if (hp.frame !== undefined && hp.frame !== 'last') {
      const k = parseInt(hp.frame, 10);
      if (!isNaN(k)) frame = Math.min(Math.max(k, 0), D.times.length - 1);
    }

    function drawLegend() {
      const clipped = trueMax > colourMax * (1 + 1e-9);
      const c = document.createElement('canvas');
      c.width = 240; c.height = 14;
      const g = c.getContext('2d');
      const rgb = [0, 0, 0];
      for (let x = 0; x < (clipped ? 220 : 240); ++x) {
        viridis(x / ((clipped ? 220 : 240) - 1), rgb, 0);
        g.fillStyle = 'rgb(' + rgb.map((v) => Math.round(255 * v)).join(',') + ')';
        g.fillRect(x, 0, 1, 14);
      }
      if (clipped) { g.fillStyle = '#f0f'; g.fillRect(220, 0, 20, 14); }
      let text = '<span>0</span>';
      legend.innerHTML = '';
      legend.insertAdjacentHTML('beforeend', '<span>distance to the reference:</span><span>0</span>');
      legend.appendChild(c);
      text = '<span>' + (1e3 * colourMax).toPrecision(3) + ' mm</span>';
      if (clipped) {
        const at = D.colour.true_max_at;
        text += ' <span class="dbv-clip">clipped at ' + (1e3 * colourMax).toPrecision(3) +
          ' mm: magenta is beyond; true maximum ' + fmtMm(trueMax) +
          (at ? ' (' + esc(at[0]) + ', t = ' + Number(at[1]).toFixed(3) + ' s)' : '') + '</span>';
      } else {
        text += ' <span>(the full range: the largest distance of any run at any frame is ' + fmtMm(trueMax) + ')</span>';
      }
      if (perPanel) text = '<span>each panel its own maximum (named in its box)</span>';
      if (refIndex == null) text = '<span>no reference in this folder: surfaces uniform</span>';
      legend.insertAdjacentHTML('beforeend', text);
    }

    function layout() {
      const w = stage.clientWidth, h = stage.clientHeight;
      const k = panels.length;
      let best = null;
      for (let cols = 1; cols <= k; ++cols) {
        const rows = Math.ceil(k / cols);
        const pw = w / cols, ph = h / rows;
        const s = Math.min(pw, ph * 1.3);
        if (!best || s > best.s) best = { cols, rows, s };
      }
      const pw = Math.floor(w / best.cols), ph = Math.floor(h / best.rows);
      panels.forEach((p, j) => {
        const c = j % best.cols, r = Math.floor(j / best.cols);
        p.rect = { x: c * pw, y: r * ph, w: pw - 2, h: ph - 2 };
        p.label.style.left = (p.rect.x + 4) + 'px';
        p.label.style.top = (p.rect.y + 4) + 'px';
        p.label.style.maxWidth = Math.max(p.rect.w - 16, 60) + 'px';
      });
      renderer.setSize(w, h, false);
      stage.setAttribute('data-panels', panels.map((p) => [p.rect.x, p.rect.y, p.rect.w, p.rect.h].join(',')).join(';'));
    }

    function update() {
      const t = D.times[frame];
      const refSeries = refIndex != null ? series[refIndex] : null;
      const refRun = refIndex != null ? D.runs[refIndex] : null;
      const refLocal = refRun ? refRun.times.indexOf(t) : -1;
      const refPos = refLocal >= 0 ? refSeries.at(refLocal) : null;
      const ref2 = refPos ? Float32Array.from(refPos) : null;  // at() reuses its buffer
      for (const p of panels) {
        const s = series[p.i], run = p.run;
        const lf = localFrame(run, t);
        const x = s.at(lf);
        p.pos.array.set(x);
        p.pos.needsUpdate = true;
        const exact = run.times[lf] === t;
        const c = p.col.array;
        let fmax = null;
        const cmax = perPanel ? (panelMax(p.i) || colourMax) : colourMax;
        if (p.i !== refIndex && ref2 && exact) {
          fmax = 0;
          for (let v = 0; v < n; ++v) {
            const dx = x[3 * v] - ref2[3 * v], dy = x[3 * v + 1] - ref2[3 * v + 1], dz = x[3 * v + 2] - ref2[3 * v + 2];
            const e = Math.sqrt(dx * dx + dy * dy + dz * dz);
            if (e > fmax) fmax = e;
            if (e > cmax * (1 + 1e-9)) { c[3 * v] = OVER[0]; c[3 * v + 1] = OVER[1]; c[3 * v + 2] = OVER[2]; } else viridis(e / cmax, c, 3 * v);
          }
        } else {
          for (let v = 0; v < n; ++v) { c[3 * v] = NEUTRAL[0]; c[3 * v + 1] = NEUTRAL[1]; c[3 * v + 2] = NEUTRAL[2]; }
        }
        p.col.needsUpdate = true;
        p.geom.computeVertexNormals();
        p.geom.computeBoundingSphere();
        for (const [pp] of [[p.fixedPts], [p.graspPts]]) {
          pp.idx.forEach((v, j) => { pp.a.array[3 * j] = x[3 * v]; pp.a.array[3 * j + 1] = x[3 * v + 1]; pp.a.array[3 * j + 2] = x[3 * v + 2]; });
          pp.a.needsUpdate = true;
          pp.g.computeBoundingSphere();
        }
        for (const tl of p.tools) {
          const st = lerpTool(tl.t, t);
          if (st) {
            tl.m.position.set(st.pos[0], st.pos[1], st.pos[2]);
            tl.m.material.color.setHex(st.jaw === 'closed' ? 0xc03000 : 0x808080);
          }
        }
        const distinct = run.distinct || [];
        const fmtP = ([k, v]) => k + '=' + (typeof v === 'number' ? +v.toPrecision(6) : v);
        const entries = Object.entries(run.params || {});
        let params = entries.filter(([k]) => distinct.includes(k)).map((kv) => '<b>' + esc(fmtP(kv)) + '</b>').join(', ');
        const others = entries.length - distinct.length;
        if (others > 0 && !params) params = others + ' parameters (the label names those not at their default)';
        const valid = run.valid === false ? '<span class="bad">invalid' + (run.invalid_reason ? ': ' + esc(run.invalid_reason) : '') + '</span>'
          : run.valid === true ? '<span class="good">valid</span>' : '';
        const st = run.status === 'ok' ? '<span class="good">ok</span>' : '<span class="bad">' + esc(run.status) + '</span>';
        let lines = '<b>' + esc(run.label) + (p.i === refIndex ? ' [reference]' : '') + '</b>';
        if (params) lines += '<br>' + params;
        lines += '<br>' + st + (valid ? ' &middot; ' + valid : '') + ' &middot; ' +
          (run.step_ms != null ? run.step_ms.toPrecision(3) + ' ms/step' : 'no step time');
        if (p.i !== refIndex) {
          lines += '<br>rmse_all ' + fmtMm(run.rmse_all_m) + ' &middot; max ' + fmtMm(run.max_m) + ' (compared instants)';
          if (run.reference_valid === false) lines += '<br><span class="bad">against an invalid reference' + (run.reference_invalid_reason ? ': ' + esc(run.reference_invalid_reason) : '') + '</span>';
          lines += '<br>' + (fmax != null ? 'this frame: max ' + fmtMm(fmax) : (exact ? 'no reference surface at this time' : 'no surface at this time: showing t = ' + run.times[lf].toFixed(3) + ' s'));
          if (perPanel) lines += '<br>colour scale 0 to ' + fmtMm(cmax) + ' (this panel)';
        } else if (!exact) {
          lines += '<br>no surface at this time: showing t = ' + run.times[lf].toFixed(3) + ' s';
        }
        if (run.grasp_residual_m != null) lines += '<br>grasp residual ' + fmtMm(run.grasp_residual_m);
        if (run.message) lines += '<br>' + esc(run.message.slice(0, 120));
        p.label.innerHTML = lines;
        p.label.setAttribute('data-frame-max-mm', fmax != null ? (1e3 * fmax).toPrecision(4) : '');
      }
      slider.value = String(frame);
      timeText.textContent = 't = ' + t.toFixed(3) + ' s (frame ' + (frame + 1) + ' of ' + D.times.length +
        (D.thinned ? '; every ' + D.thinned + 'th of ' + D.frames_written + ' written frames, to bound the size' : '') + ')';
      render();
    }

    function render() {
      renderer.setScissorTest(false);
      renderer.setClearColor(0xffffff);
      renderer.clear();
      renderer.setScissorTest(true);
      const H = stage.clientHeight;
      for (const p of panels) {
        const r = p.rect;
        renderer.setViewport(r.x, H - r.y - r.h, r.w, r.h);
        renderer.setScissor(r.x, H - r.y - r.h, r.w, r.h);
        camera.aspect = r.w / r.h;
        // The organ sits right of and below the panel's centre, clear of its info box (top left).
        camera.setViewOffset(r.w, r.h, -0.1 * r.w, -0.12 * r.h, r.w, r.h);
        camera.updateProjectionMatrix();
        p.light.position.copy(camera.position);
        p.light.target.position.copy(controls.target);
        renderer.render(p.scene, camera);
      }
    }

    slider.addEventListener('input', () => { frame = parseInt(slider.value, 10); update(); });
    controls.addEventListener('change', render);
    root.querySelector('.dbv-reset').addEventListener('click', () => { controls.reset(); render(); });
    scaleSelect.addEventListener('change', () => {
      perPanel = scaleSelect.value === 'panel';
      maxInput.disabled = perPanel;
      drawLegend(); update();
    });
    maxInput.disabled = perPanel;
    maxInput.addEventListener('change', () => {
      const v = parseFloat(maxInput.value) / 1e3;
      if (v > 0) { colourMax = v; drawLegend(); update(); }
    });
    root.querySelector('.dbv-truemax').addEventListener('click', () => {
      colourMax = trueMax > 0 ? trueMax : colourMax;
      maxInput.value = (1e3 * colourMax).toPrecision(4);
      drawLegend(); update();
    });
    let playing = null;
    const playBtn = root.querySelector('.dbv-play');
    function play(on) {
      if (playing) { clearInterval(playing); playing = null; }
      playBtn.textContent = on ? 'pause' : 'play';
      if (!on) return;
      if (frame >= D.times.length - 1) frame = 0;
      playing = setInterval(() => {
        frame = frame + 1 >= D.times.length ? 0 : frame + 1;
        update();
      }, 1000 / 12);
    }
    playBtn.addEventListener('click', () => play(!playing));
    if (D.times.length < 2) { playBtn.disabled = true; slider.disabled = true; }
    window.addEventListener('resize', () => { layout(); render(); });
    window.addEventListener('hashchange', () => {
      const h = hashParams();
      if (h.frame !== undefined) {
        frame = h.frame === 'last' ? D.times.length - 1 : Math.min(Math.max(parseInt(h.frame, 10) || 0, 0), D.times.length - 1);
        update();
      }
    });
    layout();
    home(panels[0].rect.w / panels[0].rect.h);
    drawLegend();
    update();
    if (hp.play === '1') play(true);
    status.textContent = D.runs.length + ' runs, ' + n + ' vertices, ' +
      (D.times.length > 1 ? D.times.length + ' frames' : 'the final surfaces only (the scene\'s "output": {"surfaces": "every:N"} writes a series)') + '; surfaces ' +
      (D.encoded_bytes / 1e6).toFixed(2) + ' MB encoded' +
      ((D.absent || []).length ? '. Not drawn (no surface): ' +
        D.absent.map((a) => a.label + ': ' + a.status + (a.message ? ' (' + a.message + ')' : '')).join('; ') : '');
    document.body.setAttribute('data-viewer-status', 'ready');
    document.body.setAttribute('data-viewer-frame', String(frame));
    document.body.setAttribute('data-viewer-scale', perPanel ? 'panel' : 'shared');
    const sr = stage.getBoundingClientRect();
    document.body.setAttribute('data-viewer-stage', [sr.left + window.scrollX, sr.top + window.scrollY, sr.width, sr.height].map(Math.round).join(','));
  }

  if (!window.THREE || !THREE.OrbitControls) {
    fail('error: three.js did not load');
  } else if (typeof DecompressionStream === 'undefined') {
    fail('error: this browser has no DecompressionStream (Chromium 80, Firefox 113, Safari 16.4 or later needed)');
  } else {
    main().catch((e) => fail('error: ' + (e && e.stack || e)));
  }
}());
