#pragma once

// The page of runtime/view.hpp: its HTML, style and script, written beside the data
// (data.js) by write_view. Written for vmap (no third-party code), as classic scripts
// (a page opened from the file system may not load modules), with no network access:
// the key images (img/), the loops' matches (matches/) and the data are files of the
// page's folder, loaded by <img> and <script> elements, which browsers allow for files.
//
// The page exposes window.vmapView for tests and scripts: `ready`, `mode` ("map" or
// "line"), `marks` and `lines` (key images and loop edges drawn), `answerMarks`, `up`,
// `placed` (the answers placed: {image, key}), `selected`, and `select(k)`, `screenOf(k)`
// (a key image's mark in the map canvas, CSS pixels from its top left), `setMode(m)`,
// `mapPixels()` (pixels of the map canvas that are not its background), `pair` (the last
// loop drawn: {loop, matches}).

#include <string_view>

namespace vmap::detail {

inline constexpr std::string_view view_index_html = R"vmap(<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>vmap view</title>
<link rel="icon" href="data:,">
<link rel="stylesheet" href="view.css">
</head>
<body>
<header>
  <h1 id="title">vmap view</h1>
  <dl id="summary"></dl>
</header>
<main>
  <section id="map-pane">
    <div class="bar">
      <button id="mode-map" type="button">Map</button>
      <button id="mode-line" type="button">Time line</button>
      <button id="fit" type="button">Fit</button>
      <span id="legend"></span>
    </div>
    <div id="map-box"><canvas id="map"></canvas><div id="unplaced"></div></div>
    <p class="hint" id="map-hint"></p>
  </section>
  <aside id="key-pane"><p class="hint">Click a key image on the map, the chart or a table.</p></aside>
</main>
<section id="chart-pane">
  <h2>Similarity of consecutive key images (eq. 5) against the threshold tau, and the map's quality (eq. 7)</h2>
  <canvas id="chart"></canvas>
  <div id="quality"></div>
</section>
<section id="answers-pane" hidden>
  <h2>Queries</h2>
  <table id="answers"></table>
</section>
<section id="loops-pane">
  <h2>Loop edges</h2>
  <table id="loops"></table>
  <button id="more" type="button" hidden>Show more</button>
</section>
<noscript>This page draws the memory with JavaScript: allow scripts for files.</noscript>
<script src="data.js"></script>
<script src="view.js"></script>
</body>
</html>
)vmap";

inline constexpr std::string_view view_style = R"vmap(
* { box-sizing: border-box; }
body { margin: 0; font: 13px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; color: #222; background: #f4f5f7; }
header { padding: 8px 14px; background: #fff; border-bottom: 1px solid #ddd; }
h1 { font-size: 16px; margin: 0 0 4px; word-break: break-all; }
h2 { font-size: 14px; margin: 0 0 6px; }
h3 { font-size: 13px; margin: 10px 0 4px; }
#summary { display: grid; grid-template-columns: repeat(auto-fill, minmax(260px, 1fr)); gap: 2px 16px; margin: 0; }
#summary div { display: flex; gap: 6px; min-width: 0; }
#summary dt { color: #666; white-space: nowrap; }
#summary dd { margin: 0; overflow: hidden; text-overflow: ellipsis; white-space: nowrap; }
main { display: grid; grid-template-columns: minmax(0, 3fr) minmax(280px, 2fr); gap: 10px; padding: 10px 14px 0; }
section, aside { background: #fff; border: 1px solid #ddd; border-radius: 4px; padding: 8px; min-width: 0; }
#chart-pane, #answers-pane, #loops-pane { margin: 10px 14px; }
.bar { display: flex; gap: 6px; align-items: center; margin-bottom: 6px; flex-wrap: wrap; }
button { font: inherit; padding: 2px 10px; border: 1px solid #bbb; background: #f8f8f8; border-radius: 3px; cursor: pointer; }
button.on { background: #2b6cb0; color: #fff; border-color: #2b6cb0; }
button[hidden] { display: none; }
#legend { display: flex; gap: 10px; flex-wrap: wrap; color: #444; }
.swatch { display: inline-block; width: 10px; height: 10px; border-radius: 2px; margin-right: 4px; vertical-align: -1px; }
#map-box { position: relative; }
#map { display: block; width: 100%; height: 460px; background: #fff; cursor: crosshair; touch-action: none; }
#unplaced { position: absolute; right: 6px; top: 6px; max-width: 60%; background: rgba(255, 255, 255, 0.9); font-size: 12px; }
#unplaced:empty { display: none; }
.hint { color: #777; margin: 4px 0 0; }
#key-pane { max-height: 600px; overflow: auto; }
#key-pane table { border-collapse: collapse; }
#key-pane td { padding: 0 10px 0 0; vertical-align: top; }
#key-pane p { margin: 4px 0; }
#key-pane td:first-child { color: #666; white-space: nowrap; }
#key-image { display: block; max-width: 100%; max-height: 170px; margin: 6px 0; border: 1px solid #ccc; }
.pair { margin: 6px 0 10px; }
.pair canvas { display: block; max-width: 100%; border: 1px solid #ccc; }
a.key { color: #2b6cb0; cursor: pointer; text-decoration: underline; }
#chart { display: block; width: 100%; height: 170px; cursor: crosshair; }
#quality { display: flex; flex-wrap: wrap; gap: 4px 18px; margin-top: 4px; }
table.list { border-collapse: collapse; width: 100%; }
table.list th, table.list td { text-align: left; padding: 2px 8px; border-bottom: 1px solid #eee; white-space: nowrap; }
table.list td.wrap { white-space: normal; }
table.list th { position: sticky; top: 0; background: #fafafa; }
table.list th.sort { cursor: pointer; color: #2b6cb0; }
table.list tr.row { cursor: pointer; }
table.list tr.row:hover { background: #eef4fb; }
.ok { color: #1d7a35; }
.no { color: #b3261e; }
@media (max-width: 800px) { main { grid-template-columns: 1fr; } }
)vmap";

inline constexpr std::string_view view_script = R"vmap((function () {
  'use strict';
  const D = window.VMAP_VIEW;
  const K = D.keys, L = D.loops, R = D.runs, A = D.answers;
  const n = K.n, nl = L.n;
  const palette = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2', '#7f7f7f', '#bcbd22', '#17becf'];
  const colourOf = (r) => palette[r % palette.length];
  const $ = (id) => document.getElementById(id);
  const hook = window.vmapView = {
    ready: false, mode: null, marks: 0, lines: 0, answerMarks: 0, keys: n, loops: nl,
    up: D.posed ? D.up : null, selected: null, pair: null,
    placed: A.filter((a) => a.key !== null).map((a) => ({ image: a.image, key: a.key }))
  };

  function el(tag, props, children) {
    const e = document.createElement(tag);
    if (props) for (const p in props) {
      if (p === 'class') e.className = props[p];
      else if (p === 'text') e.textContent = props[p];
      else if (p.startsWith('on')) e.addEventListener(p.slice(2), props[p]);
      else e.setAttribute(p, props[p]);
    }
    if (children) for (const c of children) e.append(c);
    return e;
  }
  const fixed = (x, d) => (x === null || x === undefined ? '-' : Number(x).toFixed(d));
  const runName = (r) => R[r].name;
  const keyLabel = (k) => {
    const r = K.run[k], local = k - R[r].base;
    return (D.run_kind === 'robot' ? runName(r) + ' ' : '') + 'key ' + local;
  };
  const imgPath = (k) => 'img/' + Math.floor(k / D.image_bucket) + '/' + k + '.jpg';

  // The loop edges of each key image (both ends), and the answers placed on it.
  const loopStart = new Int32Array(n + 1);
  for (let i = 0; i < nl; i++) { loopStart[L.from[i] + 1]++; loopStart[L.to[i] + 1]++; }
  for (let k = 0; k < n; k++) loopStart[k + 1] += loopStart[k];
  const loopAt = new Int32Array(2 * nl);
  {
    const fill = loopStart.slice(0, n);
    for (let i = 0; i < nl; i++) { loopAt[fill[L.from[i]]++] = i; loopAt[fill[L.to[i]]++] = i; }
  }
  const answersAt = new Map();
  A.forEach((a, i) => { if (a.key !== null) { if (!answersAt.has(a.key)) answersAt.set(a.key, []); answersAt.get(a.key).push(i); } });

  // ---- summary ----------------------------------------------------------------------
  $('title').textContent = D.title;
  document.title = 'vmap view: ' + D.title;
  for (const [label, value] of D.summary)
    $('summary').append(el('div', null, [el('dt', { text: label }), el('dd', { text: value, title: value })]));
  const legend = $('legend');
  R.slice(0, 24).forEach((r, i) => {
    const s = el('span', { class: 'swatch' });
    s.style.background = colourOf(i);
    legend.append(el('span', null, [s, r.name + ' (' + r.count + ')']));
  });
  if (R.length > 24) legend.append(el('span', { text: 'and ' + (R.length - 24) + ' more' }));
  if (nl > 0) {
    const s = el('span', { class: 'swatch' });
    s.style.background = '#c0392b';
    legend.append(el('span', null, [s, 'loop edges (' + nl + ')']));
  }

  // ---- the map: from above (poses) or the time line ------------------------------------
  const canvas = $('map'), ctx = canvas.getContext('2d');
  const background = [255, 255, 255];
  let mode = D.posed ? 'map' : 'line';
  let wx = new Float64Array(n), wy = new Float64Array(n);
  let scale = 1, ox = 0, oy = 0, cssW = 0, cssH = 0, dpr = 1;
  const gap = Math.max(1, Math.round(n / 200));  // key images between two runs on the time line

  function layout() {
    if (mode === 'map') {
      const P = K.position, a = D.plane[0], b = D.plane[1];
      for (let k = 0; k < n; k++) { wx[k] = P[3 * k + a]; wy[k] = P[3 * k + b]; }
    } else {
      for (let k = 0; k < n; k++) { wx[k] = k + K.run[k] * gap; wy[k] = 0; }
    }
  }
  function sx(k) { return wx[k] * scale + ox; }
  function sy(k) { return mode === 'map' ? oy - wy[k] * scale : cssH * 0.82; }
  function size() {
    dpr = window.devicePixelRatio || 1;
    cssW = canvas.clientWidth; cssH = canvas.clientHeight;
    canvas.width = Math.max(1, Math.round(cssW * dpr)); canvas.height = Math.max(1, Math.round(cssH * dpr));
  }
  function fit() {
    if (n === 0) return;
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (let k = 0; k < n; k++) {
      x0 = Math.min(x0, wx[k]); x1 = Math.max(x1, wx[k]); y0 = Math.min(y0, wy[k]); y1 = Math.max(y1, wy[k]);
    }
    if (mode === 'map' && A.length) for (const a of A) if (a.pose && a.pose.u !== undefined) {
      x0 = Math.min(x0, a.pose.u); x1 = Math.max(x1, a.pose.u); y0 = Math.min(y0, a.pose.v); y1 = Math.max(y1, a.pose.v);
    }
    const m = 24, w = Math.max(x1 - x0, 1e-9), h = Math.max(y1 - y0, 1e-9);
    if (mode === 'map') {
      scale = Math.min((cssW - 2 * m) / w, (cssH - 2 * m) / h);
      if (!isFinite(scale) || scale <= 0) scale = 1;
      ox = cssW / 2 - (x0 + x1) / 2 * scale; oy = cssH / 2 + (y0 + y1) / 2 * scale;
    } else {
      scale = (cssW - 2 * m) / Math.max(x1 - x0, 1);
      ox = m - x0 * scale; oy = 0;
    }
  }

  let pending = false;
  function redraw() { if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; draw(); }); } }
  // The map's own drawing (the runs' chains, the loop edges, the marks) is kept in a canvas
  // of its own, drawn again only when the view moves; a selection and the answers are drawn
  // over a copy of it. Marks and lines that fall on the same pixels are drawn once (a large
  // memory has many key images per pixel): `marks` counts the key images with a mark on the
  // canvas and `lines` the loop edges drawn, alone or on a line they share.
  const layer = document.createElement('canvas'), lctx = layer.getContext('2d');
  let layerDirty = true, stamp = new Int32Array(0);
  function moved() { layerDirty = true; redraw(); }
  function drawLayer() {
    const c = lctx;
    layer.width = canvas.width; layer.height = canvas.height;
    c.setTransform(dpr, 0, 0, dpr, 0, 0);
    c.fillStyle = 'rgb(' + background.join(',') + ')';
    c.fillRect(0, 0, cssW, cssH);
    const base = cssH * 0.82;
    c.lineWidth = 1;
    for (let r = 0; r < R.length; r++) {
      if (R[r].count < 2) continue;
      c.strokeStyle = colourOf(r); c.globalAlpha = 0.35;
      c.beginPath();
      let px = NaN, py = NaN;
      for (let k = R[r].first; k < R[r].first + R[r].count; k++) {
        const x = Math.round(sx(k)), y = Math.round(sy(k));
        if (x === px && y === py) continue;
        if (k === R[r].first) c.moveTo(x, y); else c.lineTo(x, y);
        px = x; py = y;
      }
      c.stroke();
    }
    c.globalAlpha = 0.55; c.strokeStyle = '#c0392b'; c.lineWidth = 1.2;
    c.beginPath();
    let lines = 0;
    const seen = new Set();
    for (let i = 0; i < nl; i++) {
      const a = L.from[i], b = L.to[i];
      const xa = Math.round(sx(a)), xb = Math.round(sx(b)), ya = Math.round(sy(a)), yb = Math.round(sy(b));
      lines++;
      const id = xa + ',' + ya + ',' + xb + ',' + yb;
      if (seen.has(id)) continue;
      seen.add(id);
      if (mode === 'map') {
        c.moveTo(xa, ya); c.lineTo(xb, yb);
      } else {
        const cx = (xa + xb) / 2, rx = Math.max(Math.abs(xb - xa) / 2, 0.5), ry = Math.min(rx, base - 8);
        c.moveTo(Math.max(xa, xb), base);
        c.ellipse(cx, base, rx, ry, 0, 0, Math.PI, true);
      }
    }
    c.stroke();
    c.globalAlpha = 1;
    // One mark per key image, one colour per run.
    const r0 = n > 20000 ? 1.5 : n > 2000 ? 2 : 3;
    const W = Math.ceil(cssW) + 1, H = Math.ceil(cssH) + 1;
    if (stamp.length !== W * H) stamp = new Int32Array(W * H);
    stamp.fill(0);
    let marks = 0;
    for (let r = 0; r < R.length; r++) {
      c.fillStyle = colourOf(r);
      c.beginPath();
      for (let k = R[r].first; k < R[r].first + R[r].count; k++) {
        const x = Math.round(sx(k)), y = Math.round(sy(k));
        if (x < 0 || y < 0 || x >= W || y >= H) continue;
        marks++;
        if (stamp[y * W + x] === r + 1) continue;
        stamp[y * W + x] = r + 1;
        c.rect(x - r0, y - r0, 2 * r0, 2 * r0);
      }
      c.fill();
    }
    hook.marks = marks; hook.lines = lines;
    layerDirty = false;
  }

  function draw() {
    if (layerDirty) drawLayer();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.drawImage(layer, 0, 0);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    // Answers: a ring on each accepted query's key image, its metric pose where answered.
    let answerMarks = 0;
    ctx.lineWidth = 2; ctx.strokeStyle = '#111';
    for (const a of A) {
      if (a.key === null) continue;
      const x = sx(a.key), y = sy(a.key);
      if (mode === 'map' && a.pose && a.pose.u !== undefined) {
        const px = a.pose.u * scale + ox, py = oy - a.pose.v * scale;
        ctx.setLineDash([3, 3]); ctx.beginPath(); ctx.moveTo(px, py); ctx.lineTo(x, y); ctx.stroke(); ctx.setLineDash([]);
        ctx.fillStyle = '#111'; ctx.beginPath();
        ctx.moveTo(px, py - 7); ctx.lineTo(px + 6, py + 5); ctx.lineTo(px - 6, py + 5); ctx.closePath(); ctx.fill();
      }
      ctx.beginPath(); ctx.arc(x, mode === 'map' ? y : y - 10, 7, 0, 2 * Math.PI); ctx.stroke();
      answerMarks++;
    }
    if (hook.selected !== null) {
      const k = hook.selected;
      ctx.lineWidth = 3; ctx.strokeStyle = '#000';
      ctx.beginPath(); ctx.arc(sx(k), sy(k), 9, 0, 2 * Math.PI); ctx.stroke();
    }
    hook.answerMarks = answerMarks;
  }

  function pick(mx, my) {
    let best = -1, bd = 12 * 12;
    for (let k = 0; k < n; k++) {
      const dx = sx(k) - mx, dy = sy(k) - my, d = dx * dx + dy * dy;
      if (d < bd) { bd = d; best = k; }
    }
    return best;
  }

  let drag = null;
  canvas.addEventListener('pointerdown', (e) => {
    drag = { x: e.offsetX, y: e.offsetY, ox, oy, moved: false };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.offsetX - drag.x, dy = e.offsetY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
    if (!drag.moved) return;
    ox = drag.ox + dx; if (mode === 'map') oy = drag.oy + dy;
    moved();
  });
  canvas.addEventListener('pointerup', (e) => {
    const d = drag; drag = null;
    if (d && !d.moved) { const k = pick(e.offsetX, e.offsetY); if (k >= 0) select(k); }
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const f = Math.exp(-e.deltaY * 0.0015);
    ox = e.offsetX - (e.offsetX - ox) * f;
    if (mode === 'map') oy = e.offsetY - (e.offsetY - oy) * f;
    scale *= f;
    moved();
  }, { passive: false });

  function setMode(m) {
    if (m === 'map' && !D.posed) return;
    mode = m; hook.mode = m;
    $('mode-map').classList.toggle('on', m === 'map');
    $('mode-line').classList.toggle('on', m === 'line');
    $('map-hint').textContent = m === 'map'
      ? 'Seen from above: up is ' + D.up + ', right is +' + 'xyz'[D.plane[0]] + ', top is +' + 'xyz'[D.plane[1]] + '. Drag to move, wheel to zoom.'
      : 'The key images in order (the runs one after the other), loop edges as arcs. Drag to move, wheel to zoom.';
    layout(); fit(); layerDirty = true; draw();
  }
  hook.setMode = setMode;
  $('mode-map').hidden = !D.posed;
  $('mode-line').hidden = !D.posed;
  $('mode-map').addEventListener('click', () => setMode('map'));
  $('mode-line').addEventListener('click', () => setMode('line'));
  $('fit').addEventListener('click', () => { fit(); layerDirty = true; draw(); });
  hook.screenOf = (k) => ({ x: sx(k), y: sy(k) });
  hook.mapPixels = () => {
    const d = ctx.getImageData(0, 0, canvas.width, canvas.height).data;
    let c = 0;
    for (let i = 0; i < d.length; i += 4)
      if (d[i] !== background[0] || d[i + 1] !== background[1] || d[i + 2] !== background[2]) c++;
    return c;
  };

  // ---- the unplaced queries -------------------------------------------------------------
  {
    const reasons = new Map();
    for (const a of A) if (a.key === null) reasons.set(a.status, (reasons.get(a.status) || 0) + 1);
    const parts = [];
    reasons.forEach((c, s) => parts.push(s + ' (' + c + ')'));
    const total = A.length - hook.placed.length;
    if (total > 0) $('unplaced').textContent = total + (total === 1 ? ' query' : ' queries') + ' not placed: ' + parts.join(', ');
  }

  // ---- a key image --------------------------------------------------------------------
  const chunks = new Map();
  window.vmapMatches = (c, loops) => { const w = chunks.get(c); if (w) w.resolve(loops); };
  function matchesOf(i) {
    const c = Math.floor(i / D.match_chunk);
    if (!chunks.has(c)) {
      let resolve, reject;
      const p = new Promise((ok, ko) => { resolve = ok; reject = ko; });
      chunks.set(c, { promise: p, resolve, reject });
      const s = document.createElement('script');
      s.src = 'matches/' + c + '.js';
      s.onerror = () => reject(new Error('matches/' + c + '.js'));
      document.body.append(s);
    }
    return chunks.get(c).promise.then((loops) => loops[i] || []);
  }
  function loadImage(k) {
    return new Promise((resolve) => {
      if (!K.image[k]) { resolve(null); return; }
      const img = new Image();
      img.onload = () => resolve(img);
      img.onerror = () => resolve(null);
      img.src = imgPath(k);
    });
  }
  function drawPair(cv, i, a, b) {
    const W = 260;
    Promise.all([loadImage(a), loadImage(b), L.matched[i] ? matchesOf(i) : Promise.resolve([])]).then(([ia, ib, pts]) => {
      const sa = W / Math.max(K.width[a] || 1, 1), sb = W / Math.max(K.width[b] || 1, 1);
      const ha = (K.height[a] || W) * sa, hb = (K.height[b] || W) * sb;
      const H = Math.max(ha, hb, 40);
      const r = window.devicePixelRatio || 1;
      cv.width = Math.round(2 * W * r); cv.height = Math.round(H * r);
      cv.style.width = 2 * W + 'px';
      const c = cv.getContext('2d');
      c.setTransform(r, 0, 0, r, 0, 0);
      c.fillStyle = '#eee'; c.fillRect(0, 0, 2 * W, H);
      if (ia) c.drawImage(ia, 0, 0, W, ha);
      if (ib) c.drawImage(ib, W, 0, W, hb);
      c.fillStyle = '#333';
      if (!ia) c.fillText('no image of ' + keyLabel(a), 8, 16);
      if (!ib) c.fillText('no image of ' + keyLabel(b), W + 8, 16);
      c.strokeStyle = 'rgba(46, 204, 64, 0.8)'; c.lineWidth = 1;
      c.beginPath();
      for (let j = 0; j + 3 < pts.length; j += 4) {
        c.moveTo(pts[j] / 10 * sa, pts[j + 1] / 10 * sa);
        c.lineTo(W + pts[j + 2] / 10 * sb, pts[j + 3] / 10 * sb);
      }
      c.stroke();
      hook.pair = { loop: i, matches: pts.length / 4 };
    }).catch(() => { hook.pair = { loop: i, matches: 0 }; });
  }
  function keyLink(k, text) {
    return el('a', { class: 'key', text: text || keyLabel(k), onclick: () => select(k) });
  }
  function select(k) {
    hook.selected = k;
    const r = K.run[k], pane = $('key-pane');
    pane.textContent = '';
    pane.append(el('h2', { text: keyLabel(k) + ' (' + K.name[k] + ')' }));
    const rows = [
      ['name', K.name[k]], ['frame', String(K.frame[k])], ['time', fixed(K.time[k], 6) + ' s'],
      [D.run_kind, runName(r) + (D.run_kind === 'robot' ? ', session ' + K.session[k] : '')]
    ];
    if (D.posed) rows.push(['position', [0, 1, 2].map((i) => fixed(K.position[3 * k + i], 3)).join(', ') + ' m']);
    rows.push(['to the key image before', K.link[k] >= 0 ? K.link[k] + ' inliers, S = ' + fixed(K.similarity[k], 3) : 'none (first of its ' + D.run_kind + ')']);
    const next = k + 1 < n && K.run[k + 1] === r ? k + 1 : -1;
    rows.push(['to the key image after', next >= 0 && K.link[next] >= 0 ? K.link[next] + ' inliers, S = ' + fixed(K.similarity[next], 3) : 'none']);
    rows.push(['loop edges', String(loopStart[k + 1] - loopStart[k])]);
    const t = el('table');
    for (const [a, b] of rows) t.append(el('tr', null, [el('td', { text: a }), el('td', { text: b })]));
    pane.append(t);
    const nav = el('p');
    if (k > 0 && K.run[k - 1] === r) nav.append(keyLink(k - 1, '< previous'), ' ');
    if (next >= 0) nav.append(keyLink(next, 'next >'));
    pane.append(nav);
    if (K.image[k]) pane.append(el('img', { id: 'key-image', src: imgPath(k), alt: K.name[k] }));
    else pane.append(el('p', { class: 'hint', id: 'key-no-image', text: 'No image of this key image on the page (' + (D.summary.find((s) => s[0] === 'images') || ['', 'none'])[1] + ').' }));
    for (const i of answersAt.get(k) || []) {
      const a = A[i];
      pane.append(el('p', { text: 'query ' + a.image + ': ' + a.status + ', confidence ' + fixed(a.confidence, 2) + (a.pose ? ', pose ' + a.pose.position.map((x) => fixed(x, 3)).join(', ') + ' m' : '') }));
    }
    const count = loopStart[k + 1] - loopStart[k];
    if (count > 0) pane.append(el('h3', { text: 'Loop edges (' + count + ')' }));
    for (let j = loopStart[k]; j < Math.min(loopStart[k + 1], loopStart[k] + 12); j++) {
      const i = loopAt[j], other = L.from[i] === k ? L.to[i] : L.from[i];
      const p = el('div', { class: 'pair' });
      p.append(el('div', null, [keyLabel(k) + ' and ', keyLink(other), ' (' + runName(K.run[other]) + '): ' + L.inliers[i] + ' inliers, confidence ' + fixed(L.confidence[i], 2) + ', BoW ' + fixed(L.bow[i], 3) + (L.matched[i] ? '' : ' (matches not drawn)')]));
      const cv = el('canvas');
      p.append(cv);
      pane.append(p);
      drawPair(cv, i, L.from[i], L.to[i]);
    }
    if (count > 12) pane.append(el('p', { class: 'hint', text: 'and ' + (count - 12) + ' more in the table below' }));
    draw(); drawChart();
  }
  hook.select = select;

  // ---- the loops' table ---------------------------------------------------------------
  const loopCols = [
    { name: 'loop', value: (i) => i },
    { name: 'key image', value: (i) => L.from[i], text: (i) => keyLabel(L.from[i]) },
    { name: D.run_kind, value: (i) => K.run[L.from[i]] * 4294967296 + K.run[L.to[i]], text: (i) => runName(K.run[L.from[i]]) + (K.run[L.from[i]] === K.run[L.to[i]] ? '' : ' - ' + runName(K.run[L.to[i]])) },
    { name: 'revisits', value: (i) => L.to[i], text: (i) => keyLabel(L.to[i]) },
    { name: 'inliers', value: (i) => L.inliers[i] },
    { name: 'confidence', value: (i) => L.confidence[i], text: (i) => fixed(L.confidence[i], 3) },
    { name: 'BoW score', value: (i) => L.bow[i], text: (i) => fixed(L.bow[i], 3) }
  ];
  let order = Array.from({ length: nl }, (_, i) => i), shown = 200, sortedBy = 0, descending = false;
  function renderLoops() {
    const t = $('loops');
    t.textContent = '';
    t.className = 'list';
    if (nl === 0) { t.append(el('tr', null, [el('td', { text: 'No loop edge.' })])); return; }
    const head = el('tr');
    loopCols.forEach((c, j) => head.append(el('th', { class: 'sort', text: c.name + (sortedBy === j ? (descending ? ' v' : ' ^') : ''), onclick: () => sortLoops(j) })));
    t.append(head);
    const frag = document.createDocumentFragment();
    for (let r = 0; r < Math.min(shown, nl); r++) {
      const i = order[r], tr = el('tr', { class: 'row', onclick: () => select(L.from[i]) });
      for (const c of loopCols) tr.append(el('td', { text: c.text ? c.text(i) : String(c.value(i)) }));
      frag.append(tr);
    }
    t.append(frag);
    $('more').hidden = shown >= nl;
    $('more').textContent = 'Show more (' + (nl - Math.min(shown, nl)) + ' not shown)';
  }
  function sortLoops(j) {
    descending = sortedBy === j ? !descending : j >= 4;
    sortedBy = j;
    const v = loopCols[j].value, sign = descending ? -1 : 1;
    order.sort((a, b) => sign * (v(a) - v(b)) || a - b);
    renderLoops();
  }
  hook.sortLoops = (name) => sortLoops(loopCols.findIndex((c) => c.name === name));
  $('more').addEventListener('click', () => { shown += 1000; renderLoops(); });

  // ---- the similarity along the run (eq. 5) and the quality (eq. 7) --------------------
  // The chart is kept in a canvas of its own too (drawn again when the window changes), the
  // selection drawn over it; a run's key images that share a pixel column are drawn as one
  // vertical stroke from their lowest to their highest similarity.
  const chart = $('chart'), cctx = chart.getContext('2d');
  const chartLayer = document.createElement('canvas'), clctx = chartLayer.getContext('2d');
  let chartDirty = true;
  const plot = { left: 34, right: 8, top: 8, bottom: 18, W: 0, H: 0, r: 1 };
  const chartX = (k) => plot.left + (n > 1 ? k / (n - 1) : 0.5) * (plot.W - plot.left - plot.right);
  const chartY = (v) => plot.top + (1 - v) * (plot.H - plot.top - plot.bottom);
  function drawChartLayer() {
    plot.r = window.devicePixelRatio || 1; plot.W = chart.clientWidth; plot.H = chart.clientHeight;
    chart.width = chartLayer.width = Math.max(1, Math.round(plot.W * plot.r));
    chart.height = chartLayer.height = Math.max(1, Math.round(plot.H * plot.r));
    const c = clctx, x = chartX, y = chartY, W = plot.W, H = plot.H;
    c.setTransform(plot.r, 0, 0, plot.r, 0, 0);
    c.fillStyle = '#fff'; c.fillRect(0, 0, W, H);
    c.strokeStyle = '#ccc'; c.fillStyle = '#666'; c.font = '11px sans-serif';
    for (const v of [0, 0.5, 1]) { c.beginPath(); c.moveTo(plot.left, y(v)); c.lineTo(W - plot.right, y(v)); c.stroke(); c.fillText(v.toFixed(1), 4, y(v) + 4); }
    c.fillText('key image', W - plot.right - 50, H - 4);
    R.forEach((run, i) => {
      const a = run.first, b = run.first + run.count - 1;
      if (b < a) return;
      if (i > 0 && R.length <= 200) { c.strokeStyle = '#bbb'; c.beginPath(); c.moveTo(x(a) - 0.5, plot.top); c.lineTo(x(a) - 0.5, H - plot.bottom); c.stroke(); }
      if (run.tau !== null) {
        c.strokeStyle = '#c0392b'; c.setLineDash([5, 4]);
        c.beginPath(); c.moveTo(x(a), y(run.tau)); c.lineTo(Math.max(x(b), x(a) + 1), y(run.tau)); c.stroke(); c.setLineDash([]);
      }
      c.strokeStyle = colourOf(i); c.beginPath();
      let on = false, column = NaN, low = 0, high = 0;
      const flush = () => { if (on) { c.lineTo(column, y(low)); c.lineTo(column, y(high)); } };
      for (let k = a; k <= b; k++) {
        if (K.link[k] < 0) { flush(); on = false; column = NaN; continue; }
        const px = Math.round(x(k)), v = K.similarity[k];
        if (px === column) { low = Math.min(low, v); high = Math.max(high, v); continue; }
        flush();
        if (!on) { c.moveTo(px, y(v)); on = true; }
        column = px; low = high = v;
      }
      flush();
      c.stroke();
    });
    chartDirty = false;
  }
  function drawChart() {
    if (chartDirty) drawChartLayer();
    cctx.setTransform(1, 0, 0, 1, 0, 0);
    cctx.drawImage(chartLayer, 0, 0);
    if (hook.selected !== null) {
      cctx.setTransform(plot.r, 0, 0, plot.r, 0, 0);
      cctx.strokeStyle = '#000'; cctx.beginPath();
      cctx.moveTo(chartX(hook.selected), plot.top); cctx.lineTo(chartX(hook.selected), plot.H - plot.bottom); cctx.stroke();
    }
  }
  chart.addEventListener('click', (e) => {
    if (n === 0) return;
    const k = Math.round((e.offsetX - plot.left) / (plot.W - plot.left - plot.right) * (n - 1));
    select(Math.min(n - 1, Math.max(0, k)));
  });
  R.slice(0, 40).forEach((run, i) => {
    const s = el('span', { class: 'swatch' });
    s.style.background = colourOf(i);
    $('quality').append(el('span', null, [s, run.name + ': Q = ' + fixed(run.quality, 3) + ' (' + run.count + ' key images of ' + run.frames + ' frames, mean S ' + fixed(run.mean_similarity, 3) + ' over ' + run.links + ' links' + (run.tau !== null ? ', tau ' + run.tau : ', tau not recorded') + ')' + (run.input ? ', from ' + run.input : '')]));
  });
  if (R.length > 40) {
    const q = R.map((run) => run.quality);
    $('quality').append(el('span', { text: 'and ' + (R.length - 40) + ' more ' + D.run_kind + 's: Q from ' + fixed(q.reduce((a, b) => Math.min(a, b)), 3) + ' to ' + fixed(q.reduce((a, b) => Math.max(a, b)), 3) }));
  }

  // ---- the queries --------------------------------------------------------------------
  if (A.length) {
    $('answers-pane').hidden = false;
    const t = $('answers');
    t.className = 'list';
    t.append(el('tr', null, ['query', 'status', 'key image', 'confidence', 'pose (m)', 'reason'].map((h) => el('th', { text: h }))));
    A.forEach((a) => {
      const pose = a.pose ? a.pose.position.map((x) => fixed(x, 3)).join(', ') : (a.pose_reason ? 'none: ' + a.pose_reason : '-');
      const tr = el('tr', { class: a.key !== null ? 'row' : '', onclick: () => { if (a.key !== null) select(a.key); } }, [
        el('td', { text: a.image }), el('td', { class: a.accepted ? 'ok' : 'no', text: a.status }),
        el('td', { text: a.key !== null ? keyLabel(a.key) : '-' }), el('td', { text: fixed(a.confidence, 3) }),
        el('td', { class: 'wrap', text: pose }), el('td', { class: 'wrap', text: a.reason })]);
      t.append(tr);
    });
  }

  // ---- start ------------------------------------------------------------------------
  size();
  setMode(mode);
  renderLoops();
  drawChart();
  window.addEventListener('resize', () => { size(); fit(); layerDirty = true; chartDirty = true; draw(); drawChart(); });
  hook.ready = true;
})();
)vmap";

}  // namespace vmap::detail
