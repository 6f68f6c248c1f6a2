"use strict";
// The fccgrb 3D view: draws the scene embedded in this page on a canvas. The projection is
// fccgrb_cli/view/camera.py's, written again here (docs/view.md); the data are the results
// file's, decimated for display only when the page says so.
(function () {
  const S = JSON.parse(document.getElementById("scene").textContent);
  const decode = (text, Type) => {
    if (text === null || text === undefined) return null;
    const raw = atob(text);
    const bytes = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    return new Type(bytes.buffer);
  };
  const time = decode(S.time, Float64Array);
  const frames = decode(S.frames, Int32Array);
  const layers = S.layers.map((L) => ({
    ...L,
    positions: decode(L.positions, Float32Array),
    lines: decode(L.lines, Int32Array),
    distance: decode(L.distance, Float32Array),
    flags: decode(L.flags, Uint16Array),
    trusted: decode(L.trusted, Uint8Array),
    curves: L.curves.map((c) => ({...c, values: decode(c.values, Float32Array),
      sd: decode(c.sd, Float32Array), trusted: decode(c.trusted, Uint8Array)})),
  }));
  const ax = S.axes;
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
    a[0] * b[1] - a[1] * b[0]];
  const comb = (a, x, b, y) => [a * x[0] + b * y[0], a * x[1] + b * y[1], a * x[2] + b * y[2]];

  const cam = {target: S.target.slice(), yaw: 0, pitch: 0, distance: S.distance,
    fov: S.fov * Math.PI / 180};
  function preset(name) {
    const [yaw, pitch] = S.presets[name];
    cam.yaw = yaw * Math.PI / 180; cam.pitch = pitch * Math.PI / 180;
    cam.target = S.target.slice(); cam.distance = S.distance;
    document.querySelectorAll("button[data-camera]").forEach(
      (b) => b.classList.toggle("on", b.dataset.camera === name));
    draw();
  }
  function basis() {
    const cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw);
    const cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
    const horizontal = comb(cy, ax.forward, sy, ax.lateral);
    const back = comb(cp, horizontal, sp, ax.up);
    const right = comb(-sy, ax.forward, cy, ax.lateral);
    return [back, right, cross(back, right)];
  }
  // camera.py's project: (x px, y px down, depth m)
  function project(p, W, H, B) {
    const [back, right, up] = B || basis();
    const eye = comb(1, cam.target, cam.distance, back);
    const d = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
    const x = dot(d, right), y = dot(d, up), z = -dot(d, back);
    const k = 0.5 * H / Math.tan(0.5 * cam.fov);
    return [0.5 * W + k * x / z, 0.5 * H - k * y / z, z];
  }

  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const slider = document.getElementById("frame");
  const clock = document.getElementById("clock");
  const status = document.getElementById("status");
  const tip = document.getElementById("tip");
  const strip = document.getElementById("flags");
  const plot = document.getElementById("curves");
  const state = {k: 0, playing: false, speed: 1, clock: time[frames[0]], labels: S.modelView,
    draws: 0, drawn: []};
  slider.max = frames.length - 1;

  function point(L, k, i) {
    const o = (k * L.nPoints + i) * 3;
    return [L.positions[o], L.positions[o + 1], L.positions[o + 2]];
  }
  function frameTrusted(L, f) { return !L.trusted || L.trusted[f] === 1; }
  function reasons(L, f) {
    if (frameTrusted(L, f)) return [];
    const out = L.bits.filter((b) => (L.flags[f] & b.value) !== 0).map(
      (b) => `${b.name}: ${b.meaning}` + (b.detail ? ` (${b.detail})` : ""));
    return out.length ? out : ["the solver did not converge on this frame"];
  }
  function markerState(L, k, m) {
    const p = point(L, k, L.markers[m]);
    if (!Number.isFinite(p[0])) return {bad: true, why: "missing in this frame"};
    const d = L.distance ? L.distance[k * L.markers.length + m] : NaN;
    if (d > L.limit) {
      return {bad: true, d, why: `${(1e3 * d).toFixed(1)} mm from its model point, beyond ` +
        `${(1e3 * L.limit).toFixed(0)} mm (the quality checks' limit for one marker)`};
    }
    return {bad: false, d, why: `${(1e3 * d).toFixed(1)} mm from its model point`};
  }

  function floorGrid(W, H, B) {
    const g = S.grid;
    ctx.strokeStyle = S.colors.floor; ctx.lineWidth = 1;
    for (let a = 0; a <= g.n; a++) {
      for (const dir of [0, 1]) {
        const s = g.low[dir] + a * g.step;
        const p0 = dir === 0 ? [s, g.low[1]] : [g.low[0], s];
        const p1 = dir === 0 ? [s, g.low[1] + g.n * g.step] : [g.low[0] + g.n * g.step, s];
        const w0 = comb(p0[0], ax.forward, p0[1], ax.lateral), w1 = comb(p1[0], ax.forward,
          p1[1], ax.lateral);
        line(comb(1, w0, S.floor, ax.up), comb(1, w1, S.floor, ax.up), W, H, B);
      }
    }
    const foot = comb(1, comb(g.low[0], ax.forward, g.low[1], ax.lateral), S.floor, ax.up);
    ctx.strokeStyle = S.colors.vertical; ctx.lineWidth = 2;
    const top = comb(1, foot, g.vertical, ax.up);
    line(foot, top, W, H, B);
    const q = project(top, W, H, B);
    if (q[2] > 0) { ctx.fillStyle = S.colors.vertical; ctx.fillText(S.verticalLabel, q[0] + 4, q[1]); }
  }
  function line(a, b, W, H, B) {
    const p = project(a, W, H, B), q = project(b, W, H, B);
    if (!(p[2] > 0 && q[2] > 0)) return false;
    ctx.beginPath(); ctx.moveTo(p[0], p[1]); ctx.lineTo(q[0], q[1]); ctx.stroke();
    return true;
  }

  // per layer, once: each point's kind, each marker's place among the markers
  layers.forEach((L) => {
    L.pointKind = Array.from(L.kinds, (n) => L.kindNames[n]);
    L.lineKind = Array.from(L.lineKinds, (n) => L.kindNames[n]);
    L.markerOf = new Map(L.markers.map((i, m) => [i, m]));
    L.screen = new Float64Array(3 * L.nPoints);
  });
  // strokes (or fills) batched by style: one path per colour and width
  function batched(groups, key, add) {
    if (!groups.has(key)) groups.set(key, []);
    groups.get(key).push(add);
  }

  function draw() {
    const W = canvas.width, H = canvas.height, B = basis();
    const k = state.k, f = frames[k];
    ctx.fillStyle = "#ffffff"; ctx.fillRect(0, 0, W, H);
    ctx.font = "12px sans-serif";
    floorGrid(W, H, B);
    state.drawn = [];
    // the second run first, wider and translucent: a halo where the first run covers it
    [...layers.keys()].reverse().forEach((n) => {
      const L = layers[n], overlay = n > 0, flagged = !frameTrusted(L, f);
      const keep = (kind) => !overlay || S.overlayKinds.includes(kind);
      const color = (kind) => {
        if (overlay && kind !== "marker") return S.colors.overlay;
        if (flagged && (kind === "segment" || kind === "origin")) return S.colors.flagged;
        return S.styles[kind].color;
      };
      const P = L.screen;
      for (let i = 0; i < L.nPoints; i++) {
        const q = project(point(L, k, i), W, H, B);
        P[3 * i] = q[0]; P[3 * i + 1] = q[1]; P[3 * i + 2] = q[2];
      }
      const visible = (i) => P[3 * i + 2] > 0;  // NaN (absent) and behind the eye: false
      ctx.globalAlpha = overlay ? S.overlayAlpha : 1;
      const strokes = new Map();
      for (let j = 0; j < L.lineKind.length; j++) {
        const kind = L.lineKind[j], a = L.lines[2 * j], b = L.lines[2 * j + 1];
        if (!keep(kind) || !visible(a) || !visible(b)) continue;
        batched(strokes, `${color(kind)}|${S.styles[kind].width + (overlay ? S.overlayWiden : 0)}`,
          [a, b]);
      }
      for (const [key, segments] of strokes) {
        const [c, w] = key.split("|");
        ctx.strokeStyle = c; ctx.lineWidth = Number(w); ctx.beginPath();
        for (const [a, b] of segments) {
          ctx.moveTo(P[3 * a], P[3 * a + 1]); ctx.lineTo(P[3 * b], P[3 * b + 1]);
        }
        ctx.stroke();
      }
      const fills = new Map(), texts = [];
      for (let i = 0; i < L.nPoints; i++) {
        if (!visible(i)) continue;
        const kind = L.pointKind[i], r = S.styles[kind].radius;
        let c = color(kind);
        if (L.markerOf.has(i) && markerState(L, k, L.markerOf.get(i)).bad) c = S.colors.untrusted;
        if (r > 0 && keep(kind)) batched(fills, `${c}|${r + (overlay ? S.overlayWiden / 2 : 0)}`, i);
        const label = L.labels[i];
        if (label && !overlay && (state.labels ? kind !== "marker" && kind !== "model_point"
          || S.modelView : kind === "origin")) texts.push([label, i, kind === "joint" ? 15 : -5]);
        if (label && (r > 0 || kind === "tracked_vector")) {
          state.drawn.push({x: P[3 * i], y: P[3 * i + 1], L, i, k});
        }
      }
      for (const [key, dots] of fills) {
        const [c, r] = key.split("|"), radius = Number(r);
        ctx.fillStyle = c; ctx.beginPath();
        for (const i of dots) {
          ctx.moveTo(P[3 * i] + radius, P[3 * i + 1]);
          ctx.arc(P[3 * i], P[3 * i + 1], radius, 0, 2 * Math.PI);
        }
        ctx.fill();
      }
      ctx.fillStyle = "#202020";
      for (const [label, i, dy] of texts) ctx.fillText(label, P[3 * i] + 5, P[3 * i + 1] + dy);
    });
    ctx.globalAlpha = 1;
    const lines = layers.map((L) => {
      const why = reasons(L, f);
      return why.length ? `${L.name}: frame ${f} not trusted — ${why.join("; ")}` : "";
    }).filter((t) => t);
    status.textContent = lines.join("\n");
    status.classList.toggle("flagged", lines.length > 0);
    if (!S.modelView) {
      slider.value = k;
      clock.textContent = `t = ${time[f].toFixed(3)} s · frame ${f} of ${S.nFrames}` +
        ` (0–${S.nFrames - 1})`;
      drawCurves();
    }
    state.draws += 1;
  }

  function hoverText(d) {
    const m = d.L.markerOf.get(d.i);
    const why = m === undefined ? "" : markerState(d.L, d.k, m).why;
    return `${d.L.name}: ${d.L.labels[d.i]}` + (why ? ` — ${why}` : "");
  }

  // --- the timeline ---------------------------------------------------------------------
  function setFrame(k) {
    state.k = Math.max(0, Math.min(frames.length - 1, k));
    state.clock = time[frames[state.k]];
    draw();
  }
  let last = null;
  function tick(now) {
    if (!state.playing) { last = null; return; }
    if (last !== null) {
      state.clock += (now - last) / 1000 * state.speed;
      if (state.clock > time[frames[frames.length - 1]]) state.clock = time[frames[0]];
      let k = state.k;
      while (k + 1 < frames.length && time[frames[k + 1]] <= state.clock) k++;
      while (k > 0 && time[frames[k]] > state.clock) k--;
      state.k = k;
    }
    last = now;
    draw();
    requestAnimationFrame(tick);
  }
  function play(on) {
    state.playing = on;
    document.getElementById("play").textContent = on ? "❚❚ pause" : "▶ play";
    if (on) requestAnimationFrame(tick);
  }
  function flagStrip() {
    const c = strip.getContext("2d"), W = strip.width, H = strip.height;
    c.fillStyle = "#eef3ee"; c.fillRect(0, 0, W, H);
    layers.forEach((L, n) => {
      if (!L.trusted) return;
      c.fillStyle = S.colors.flagged;
      const h = H / layers.length;
      for (let f = 0; f < S.nFrames; f++) {
        if (L.trusted[f] !== 1) c.fillRect(Math.floor(f / S.nFrames * W), n * h,
          Math.max(1, Math.ceil(W / S.nFrames)), h);
      }
    });
  }

  // --- the curves -----------------------------------------------------------------------
  const curves = layers.flatMap((L, n) => L.curves.map((c) => ({...c, layer: n})));
  const names = [...new Set(curves.map((c) => c.name))];
  // the curves drawn once per size into a picture of their own; each frame adds the cursor
  const still = document.createElement("canvas");
  const curveX = (t) => 60 + (plot.width - 70) * (t - time[0]) /
    ((time[S.nFrames - 1] - time[0]) || 1);
  function drawCurveImage() {
    still.width = plot.width; still.height = plot.height;
    const c = still.getContext("2d"), W = still.width, H = still.height;
    c.fillStyle = "#ffffff"; c.fillRect(0, 0, W, H);
    c.font = "12px sans-serif";
    const h = H / Math.max(names.length, 1);
    names.forEach((name, row) => {
      const mine = curves.filter((cv) => cv.name === name);
      let lo = Infinity, hi = -Infinity;
      for (const cv of mine) {
        for (let f = 0; f < cv.values.length; f++) {
          const s = cv.sd ? cv.sd[f] : 0, v = cv.values[f];
          if (Number.isFinite(v)) { lo = Math.min(lo, v - s); hi = Math.max(hi, v + s); }
        }
      }
      if (!(hi > lo)) { hi = lo + 1; lo -= 1; }
      const Y = (v) => row * h + 16 + (h - 26) * (hi - v) / (hi - lo);
      c.fillStyle = "#202020";
      c.fillText(`${name} (${mine[0].unit})`, 60, row * h + 12);
      c.fillText(hi.toPrecision(3), 2, Y(hi) + 4); c.fillText(lo.toPrecision(3), 2, Y(lo));
      for (const cv of [...mine].reverse()) {
        const base = cv.layer ? S.colors.overlay : S.colors.curve;
        if (cv.sd) {
          c.fillStyle = base; c.globalAlpha = S.bandAlpha; c.beginPath();
          for (let f = 0; f < cv.values.length; f++) c.lineTo(curveX(time[f]), Y(cv.values[f] + cv.sd[f]));
          for (let f = cv.values.length - 1; f >= 0; f--) c.lineTo(curveX(time[f]), Y(cv.values[f] - cv.sd[f]));
          c.fill(); c.globalAlpha = 1;
        }
        c.lineWidth = 1.5;
        for (const trusted of [true, false]) {  // the untrusted stretches grey
          c.strokeStyle = trusted ? base : "#b8b8b8"; c.beginPath();
          for (let f = 1; f < cv.values.length; f++) {
            if ((cv.trusted[f] === 1 && cv.trusted[f - 1] === 1) !== trusted) continue;
            c.moveTo(curveX(time[f - 1]), Y(cv.values[f - 1]));
            c.lineTo(curveX(time[f]), Y(cv.values[f]));
          }
          c.stroke();
        }
      }
    });
  }
  function drawCurves() {
    const c = plot.getContext("2d");
    c.drawImage(still, 0, 0);
    const x = curveX(time[frames[state.k]]);
    c.strokeStyle = "#000000"; c.lineWidth = 1;
    c.beginPath(); c.moveTo(x, 14); c.lineTo(x, plot.height - 8); c.stroke();
  }

  // --- input ----------------------------------------------------------------------------
  function size() {
    canvas.width = canvas.clientWidth; canvas.height = canvas.clientHeight;
    strip.width = strip.clientWidth; plot.width = plot.clientWidth;
    if (!S.modelView) { flagStrip(); drawCurveImage(); }
    draw();
  }
  let drag = null;
  canvas.addEventListener("pointerdown", (e) => { drag = [e.clientX, e.clientY]; });
  window.addEventListener("pointerup", () => { drag = null; });
  canvas.addEventListener("pointermove", (e) => {
    if (drag) {
      cam.yaw -= (e.clientX - drag[0]) * 0.01;
      cam.pitch = Math.max(-Math.PI / 2, Math.min(Math.PI / 2,
        cam.pitch + (e.clientY - drag[1]) * 0.01));
      drag = [e.clientX, e.clientY];
      document.querySelectorAll("button[data-camera]").forEach(
        (b) => b.classList.toggle("on", b.dataset.camera === "orbit"));
      draw();
      return;
    }
    const r = canvas.getBoundingClientRect(), x = e.clientX - r.left, y = e.clientY - r.top;
    let best = null, bestD = 10;
    for (const d of state.drawn) {
      const dd = Math.hypot(d.x - x, d.y - y);
      if (dd < bestD) { best = d; bestD = dd; }
    }
    tip.hidden = !best;
    if (best) { tip.textContent = hoverText(best); tip.style.left = `${x + 14}px`; tip.style.top = `${y + 10}px`; }
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault(); cam.distance *= Math.exp(e.deltaY * 0.001); draw();
  }, {passive: false});
  document.querySelectorAll("button[data-camera]").forEach(
    (b) => b.addEventListener("click", () => preset(b.dataset.camera)));
  document.getElementById("labels").addEventListener("change", (e) => {
    state.labels = e.target.checked; draw();
  });
  if (!S.modelView) {
    slider.addEventListener("input", () => setFrame(Number(slider.value)));
    document.getElementById("play").addEventListener("click", () => play(!state.playing));
    document.getElementById("back").addEventListener("click", () => { play(false); setFrame(state.k - 1); });
    document.getElementById("forth").addEventListener("click", () => { play(false); setFrame(state.k + 1); });
    document.getElementById("speed").addEventListener("change", (e) => { state.speed = Number(e.target.value); });
    strip.addEventListener("pointermove", (e) => {
      const r = strip.getBoundingClientRect();
      const f = Math.min(S.nFrames - 1, Math.floor((e.clientX - r.left) / r.width * S.nFrames));
      const why = layers.flatMap((L) => reasons(L, f).map((t) => `${L.name}: ${t}`));
      strip.title = `frame ${f}, t = ${time[f].toFixed(3)} s` + (why.length ? `\n${why.join("\n")}` : ": trusted");
    });
    strip.addEventListener("click", (e) => {
      const r = strip.getBoundingClientRect(), f = (e.clientX - r.left) / r.width * S.nFrames;
      let k = 0;
      while (k + 1 < frames.length && frames[k + 1] <= f) k++;
      play(false); setFrame(k);
    });
    plot.addEventListener("click", (e) => {
      const r = plot.getBoundingClientRect();
      const t = time[0] + (e.clientX - r.left - 60) / (r.width - 70) * (time[S.nFrames - 1] - time[0]);
      let k = 0;
      while (k + 1 < frames.length && time[frames[k + 1]] <= t) k++;
      play(false); setFrame(k);
    });
  }
  window.addEventListener("resize", size);
  window.fccgrbView = {state, setFrame, play, preset, project: (p) => project(p, canvas.width, canvas.height),
    camera: cam, frames, time, layers, reasons, hoverText};
  preset(S.camera);
  size();
})();
