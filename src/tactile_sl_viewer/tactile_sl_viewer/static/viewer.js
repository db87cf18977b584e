// tactile-sl live view: draws the frames the viewer node sends over one WebSocket.
// Flow control: the page asks for the next frame ("next") only once it has drawn the last
// one, on the next animation frame, so the server encodes at this page's pace (and sends
// at most its max_rate frames a second); a hidden tab (no animation frames) stops asking.
// Message layout: see packets.py.
// Cheap to draw (the browser may share the sensor's cores): opaque canvases at their native
// size (CSS scales them), text and lists written only when they changed, the colour bar and
// scale drawn once per map layout, the force and slip drawings only when their values
// moved, the stream figures twice a second.
"use strict";

(() => {
  const elements = {};
  const $ = (id) => elements[id] || (elements[id] = document.getElementById(id));
  const contexts = {};
  // every canvas is opaque (each drawing fills its background): no alpha to composite
  const ctx2d = (id) => contexts[id] || (contexts[id] = $(id).getContext("2d", { alpha: false }));
  const written = new Map();
  // text of an element, written only when it changed (no style, layout or paint otherwise)
  const setText = (id, text) => {
    if (written.get(id) === text) return;
    written.set(id, text);
    $(id).textContent = text;
  };
  const state = { ws: null, hello: null, mapKind: "pressure", shown: [], frames: 0,
                  bagIndex: 0, playing: null, lastAsk: 0, mapLayout: null, mapVmax: null,
                  forceKey: null, slipKey: null, statsAt: -1e9, diagKey: null, errorsKey: "[]",
                  img: null };
  const STATS_PERIOD_MS = 500;               // stream figures: twice a second
  // ?fps=N: ask for at most N frames a second (a slow computer, a metered link)
  const maxFps = Number(new URLSearchParams(location.search).get("fps")) || 0;
  const CLASS_RGB = ["rgb(230,60,60)", "rgb(60,200,60)", "rgb(40,140,230)"];
  const UNKNOWN_RGB = "rgb(160,160,160)";
  const VIRIDIS = [[68, 1, 84], [72, 40, 120], [62, 74, 137], [49, 104, 142], [38, 130, 142],
                   [31, 158, 137], [53, 183, 121], [109, 205, 89], [180, 222, 44],
                   [253, 231, 37]];
  const MAGMA = [[0, 0, 4], [28, 16, 68], [79, 18, 123], [129, 37, 129], [181, 54, 122],
                 [229, 80, 100], [251, 135, 97], [254, 194, 135], [252, 253, 191]];
  const lut = (stops) => {
    const out = new Uint8ClampedArray(256 * 3);
    for (let i = 0; i < 256; i++) {
      const x = (i / 255) * (stops.length - 1), k = Math.min(Math.floor(x), stops.length - 2);
      const f = x - k;
      for (let c = 0; c < 3; c++) out[3 * i + c] = stops[k][c] * (1 - f) + stops[k + 1][c] * f;
    }
    return out;
  };
  const LUTS = { pressure: lut(VIRIDIS), depth: lut(MAGMA) };
  const fmt = (x, digits) => (x === null || x === undefined || !isFinite(x)) ? "–"
    : x.toFixed(digits);

  // ------------------------------------------------------------------ connection

  function connect() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const ws = new WebSocket(`${proto}//${location.host}/ws`);
    ws.binaryType = "arraybuffer";
    ws.onopen = () => setStatus("live", "ok");
    ws.onmessage = (ev) => {
      if (typeof ev.data === "string") onText(JSON.parse(ev.data));
      else onFrame(ev.data);
    };
    ws.onclose = () => {
      setStatus("disconnected, retrying", "error");
      state.ws = null;
      setTimeout(connect, 1000);
    };
    state.ws = ws;
  }

  function send(obj) {
    if (state.ws && state.ws.readyState === WebSocket.OPEN) state.ws.send(JSON.stringify(obj));
  }
  const requestNext = () => send({ type: "next", map: state.mapKind });

  function setStatus(text, kind) {
    const el = $("status");
    el.textContent = text;
    el.className = "badge " + (kind || "");
  }

  function onText(msg) {
    if (msg.type !== "hello") return;
    state.hello = msg;
    $("source").textContent = msg.mode === "bag"
      ? `recorded bag ${msg.bag} (${msg.frames} frames)` : `live: ${msg.namespace}`;
    if (msg.mode === "bag") {
      setupBag(msg);
      setStatus(msg.decoded_here ? "recorded, decoded here" : "recorded", "ok");
      for (const row of document.querySelectorAll(".live-only")) row.hidden = true;
    }
    if (!msg.slip) $("slip-note").textContent =
      "This decoder has no slip output (tactile_sl_msgs/Slip is not built).";
    requestNext();
  }

  function parse(buf) {
    const view = new DataView(buf);
    const magic = String.fromCharCode(...new Uint8Array(buf, 0, 4));
    if (magic !== "TSLV") throw new Error("not a viewer frame");
    const length = view.getUint32(4, true);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 8, length)));
    const blobs = {};
    for (const b of header.blobs) {
      if (b.dtype === "jpeg") blobs[b.name] = new Blob([new Uint8Array(buf, b.offset, b.length)],
                                                        { type: "image/jpeg" });
      else if (b.dtype === "f4") blobs[b.name] = new Float32Array(buf, b.offset, b.length / 4);
      else if (b.dtype === "i4") blobs[b.name] = new Int32Array(buf, b.offset, b.length / 4);
      else blobs[b.name] = new Uint8Array(buf, b.offset, b.length);
    }
    return { header, blobs };
  }

  async function onFrame(buf) {
    try {
      const { header, blobs } = parse(buf);
      if (header.stamp !== undefined) await drawFrame(header, blobs);
      drawStats(header);
    } catch (err) {
      showErrors([String(err)]);
    }
    requestAnimationFrame(askWhenDue);        // the browser's pace
  }

  function askWhenDue() {
    const wait = maxFps > 0 ? state.lastAsk + 1000 / maxFps - performance.now() : 0;
    if (wait > 1) { setTimeout(askWhenDue, wait); return; }
    state.lastAsk = performance.now();
    requestNext();
  }

  // ------------------------------------------------------------------ one frame

  async function drawFrame(h, blobs) {
    await drawCamera(h, blobs);
    drawMap(h, blobs);
    drawForce(h);
    drawSlip(h);
    setText("stamp", h.stamp);
    setText("points", h.points === undefined ? "–" : String(h.points));
    if (h.bag) showBagPosition(h.bag);
    const now = performance.now();
    state.shown.push(now);
    while (state.shown.length && now - state.shown[0] > 2000) state.shown.shift();
    state.frames += 1;
    document.body.dataset.stamp = h.stamp;          // what is on screen now (tests read it)
    document.body.dataset.frames = String(state.frames);
  }

  async function drawCamera(h, blobs) {
    const canvas = $("camera"), ctx = ctx2d("camera");
    if (blobs.image) {
      const bitmap = await createImageBitmap(blobs.image);
      if (canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
        canvas.width = bitmap.width;
        canvas.height = bitmap.height;
      }
      ctx.drawImage(bitmap, 0, 0);
      bitmap.close();
    } else {
      ctx.fillStyle = "#000";
      ctx.fillRect(0, 0, canvas.width, canvas.height);
      ctx.fillStyle = "#888";
      ctx.font = "16px sans-serif";
      ctx.fillText("no image of this frame received", 20, 30);
    }
    const u = blobs.glyph_u, v = blobs.glyph_v, label = blobs.glyph_label;
    const decoded = blobs.glyph_decoded;
    if (!u) { setText("glyph-count", ""); return; }
    // one path per colour and kind: a few draw calls for hundreds of glyphs
    for (let cls = 0; cls <= 3; cls++) {
      const colour = cls < 3 ? CLASS_RGB[cls] : UNKNOWN_RGB;
      const filled = new Path2D(), ring = new Path2D();
      for (let i = 0; i < u.length; i++) {
        const c = label[i] < 3 ? label[i] : 3;
        if (c !== cls) continue;
        (decoded[i] ? filled : ring).rect(u[i] - 2.5, v[i] - 2.5, 5, 5);   // squares: cheap
      }
      ctx.fillStyle = colour;
      ctx.strokeStyle = colour;
      ctx.lineWidth = 1.2;
      ctx.fill(filled);
      ctx.stroke(ring);
    }
    setText("glyph-count", ` (${h.glyphs.count} glyphs, ${h.glyphs.decoded} decoded)`);
  }

  // ------------------------------------------------------------------ pressure / depth map

  function drawMap(h, blobs) {
    const canvas = $("map"), ctx = ctx2d("map");
    const W = canvas.width, H = canvas.height;
    if (canvas.dataset.kind !== state.mapKind) canvas.dataset.kind = state.mapKind;
    const m = h.map;
    const data = m && (m.kind === "depth" ? blobs.depth : blobs.pressure);
    if (!m || !data || m.kind !== state.mapKind) {
      const note = state.mapKind === "depth" ? "no depth map for this frame"
        : "no force field for this frame";
      if (state.mapLayout === note) return;
      state.mapLayout = note;
      ctx.fillStyle = "#000";
      ctx.fillRect(0, 0, W, H);
      ctx.fillStyle = "#888";
      ctx.font = "16px sans-serif";
      ctx.fillText(note, 20, 30);
      return;
    }
    const [rows, cols] = m.shape;
    const bar = 56, margin = 18;
    const s = Math.min((W - bar - 2 * margin) / cols, (H - 2 * margin - 24) / rows);
    const x0 = margin, y0 = margin;
    const table = LUTS[m.kind];
    const pad = h.pad;
    const perCell = m.kind === "depth" ? (rows - 1) / Math.max(pad.rows - 1, 1) : 1;
    const layout = `${m.kind} ${rows}x${cols} ${m.unit} ${pad.pitch}`;
    if (state.mapLayout !== layout) {       // the parts that stay: drawn once per layout
      state.mapLayout = layout;
      state.mapVmax = null;
      ctx.fillStyle = "#000";
      ctx.fillRect(0, 0, W, H);
      colourBar(ctx, table, W - bar + 8, y0, 14, rows * s, m.unit);
      scaleBar(ctx, x0, y0 + rows * s + 16, s * perCell, pad.pitch);
    }
    const top = `${m.vmax < 10 ? m.vmax.toFixed(1) : Math.round(m.vmax)}`;
    if (state.mapVmax !== top) {            // the scale's top: only when it changed
      state.mapVmax = top;
      ctx.fillStyle = "#000";
      ctx.fillRect(W - bar, 0, bar, y0 - 1);
      ctx.fillStyle = "#ddd";
      ctx.font = "12px sans-serif";
      ctx.fillText(top, W - bar + 4, y0 - 4);
    }
    // the map, its outline and centroid: cleared with a rim for the lines past its edge
    const rim = 10;
    ctx.fillStyle = "#000";
    ctx.fillRect(x0 - rim, y0 - rim, cols * s + 2 * rim, rows * s + 2 * rim);
    if (!state.off) state.off = document.createElement("canvas");
    const off = state.off;
    if (off.width !== cols || off.height !== rows) { off.width = cols; off.height = rows; }
    const offCtx = off.getContext("2d");
    if (!state.img || state.img.width !== cols || state.img.height !== rows) {
      state.img = offCtx.createImageData(cols, rows);
    }
    const img = state.img;
    for (let i = 0; i < rows; i++) {
      const dest = (rows - 1 - i) * cols;          // +y upwards
      for (let j = 0; j < cols; j++) {
        const value = data[i * cols + j], o = 4 * (dest + j);
        if (!isFinite(value)) {
          img.data[o] = img.data[o + 1] = img.data[o + 2] = 70;
        } else {
          const k = 3 * Math.max(0, Math.min(255, Math.round(255 * value / m.vmax)));
          img.data[o] = table[k]; img.data[o + 1] = table[k + 1]; img.data[o + 2] = table[k + 2];
        }
        img.data[o + 3] = 255;
      }
    }
    offCtx.putImageData(img, 0, 0);
    ctx.imageSmoothingEnabled = m.kind === "depth";
    ctx.drawImage(off, x0, y0, cols * s, rows * s);
    // cell (i, j) of the pressure grid / pixel of the depth map -> canvas
    const toCanvas = (x, y) => {
      const j = x / pad.pitch + (pad.cols - 1) / 2, i = y / pad.pitch + (pad.rows - 1) / 2;
      const jj = m.kind === "depth" ? j * perCell : j, ii = m.kind === "depth" ? i * perCell : i;
      return [x0 + (jj + 0.5) * s, y0 + (rows - 0.5 - ii) * s];
    };
    if (m.kind === "pressure" && blobs.contact_cells) outline(ctx, blobs.contact_cells, rows,
                                                                 cols, x0, y0, s);
    if (h.contact && h.contact.normal_force > 0) {
      const [cx, cy] = toCanvas(h.contact.centroid[0], h.contact.centroid[1]);
      ctx.strokeStyle = "rgb(255,40,40)";
      ctx.lineWidth = 2.5;
      ctx.beginPath();
      ctx.moveTo(cx - 9, cy); ctx.lineTo(cx + 9, cy); ctx.moveTo(cx, cy - 9); ctx.lineTo(cx, cy + 9);
      ctx.stroke();
    }
  }

  function outline(ctx, mask, rows, cols, x0, y0, s) {
    const inside = (i, j) => i >= 0 && i < rows && j >= 0 && j < cols && mask[i * cols + j];
    ctx.strokeStyle = "#fff";
    ctx.lineWidth = 2;
    ctx.beginPath();
    for (let i = 0; i < rows; i++) {
      for (let j = 0; j < cols; j++) {
        if (!mask[i * cols + j]) continue;
        const left = x0 + j * s, right = left + s;
        const top = y0 + (rows - 1 - i) * s, bottom = top + s;   // row i+1 is above
        if (!inside(i + 1, j)) { ctx.moveTo(left, top); ctx.lineTo(right, top); }
        if (!inside(i - 1, j)) { ctx.moveTo(left, bottom); ctx.lineTo(right, bottom); }
        if (!inside(i, j - 1)) { ctx.moveTo(left, top); ctx.lineTo(left, bottom); }
        if (!inside(i, j + 1)) { ctx.moveTo(right, top); ctx.lineTo(right, bottom); }
      }
    }
    ctx.stroke();
  }

  function colourBar(ctx, table, x, y, w, h, unit) {
    for (let k = 0; k < h; k++) {
      const i = 3 * Math.round(255 * (1 - k / h));
      ctx.fillStyle = `rgb(${table[i]},${table[i + 1]},${table[i + 2]})`;
      ctx.fillRect(x, y + k, w, 1.5);
    }
    ctx.fillStyle = "#ddd";
    ctx.font = "12px sans-serif";
    ctx.fillText("0", x + 2, y + h + 14);
    ctx.fillText(unit, x - 2, y + h + 28);
  }

  function scaleBar(ctx, x, y, cellPx, pitch) {
    const cells = Math.max(1, Math.round(0.002 / pitch));        // 2 mm
    ctx.strokeStyle = "#ddd";
    ctx.fillStyle = "#ddd";
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(x, y); ctx.lineTo(x + cells * cellPx, y);
    ctx.stroke();
    ctx.font = "12px sans-serif";
    ctx.fillText(`${(cells * pitch * 1e3).toFixed(1)} mm   x →  y ↑`, x + cells * cellPx + 8, y + 4);
  }

  // ------------------------------------------------------------------ force, moment, contact

  const niceCeil = (v) => {
    const steps = [1, 2, 5, 10];
    const e = Math.pow(10, Math.floor(Math.log10(v)));
    for (const s of steps) if (s * e >= v) return s * e;
    return 10 * e;
  };

  function arrow(ctx, x0, y0, x1, y1, colour, width) {
    const a = Math.atan2(y1 - y0, x1 - x0), len = Math.hypot(x1 - x0, y1 - y0);
    ctx.strokeStyle = colour;
    ctx.fillStyle = colour;
    ctx.lineWidth = width;
    ctx.beginPath();
    ctx.moveTo(x0, y0); ctx.lineTo(x1, y1);
    ctx.stroke();
    if (len < 4) return;
    const head = Math.min(12, 0.4 * len);
    ctx.beginPath();
    ctx.moveTo(x1, y1);
    ctx.lineTo(x1 - head * Math.cos(a - 0.4), y1 - head * Math.sin(a - 0.4));
    ctx.lineTo(x1 - head * Math.cos(a + 0.4), y1 - head * Math.sin(a + 0.4));
    ctx.closePath();
    ctx.fill();
  }

  function drawForce(h) {
    const w = h.wrench;
    drawContact(h.contact);
    // the drawing changes only with what it shows (to its resolution): redrawn only then
    const key = w ? [...w.force, w.torque[2]].map((x) => x.toFixed(4)).join(" ") : "none";
    if (key === state.forceKey) return;
    state.forceKey = key;
    const canvas = $("force"), ctx = ctx2d("force");
    const W = canvas.width, H = canvas.height, cx = W / 2 - 20, cy = H / 2, R = 120;
    ctx.fillStyle = "#111";
    ctx.fillRect(0, 0, W, H);
    if (!w) {
      ctx.fillStyle = "#888";
      ctx.font = "14px sans-serif";
      ctx.fillText("no wrench for this frame", 20, 30);
      for (const id of ["normal-force", "shear-force", "moment"]) setText(id, "–");
      return;
    }
    const [fx, fy, fz] = w.force, [mx, my, mz] = w.torque;
    const normal = -fz, shear = Math.hypot(fx, fy);
    const shearScale = niceCeil(Math.max(shear, 0.02)), normalScale = niceCeil(Math.max(Math.abs(normal), 0.05));
    // scale rings and axes (pad frame, x right, y up)
    ctx.strokeStyle = "#333";
    ctx.lineWidth = 1;
    for (const f of [0.5, 1]) { ctx.beginPath(); ctx.arc(cx, cy, R * f, 0, 2 * Math.PI); ctx.stroke(); }
    ctx.beginPath();
    ctx.moveTo(cx - R, cy); ctx.lineTo(cx + R, cy); ctx.moveTo(cx, cy - R); ctx.lineTo(cx, cy + R);
    ctx.stroke();
    ctx.fillStyle = "#999";
    ctx.font = "12px sans-serif";
    ctx.fillText(`shear (orange), ring ${shearScale} N`, 8, H - 24);
    ctx.fillText("twist Mz (blue), circle 10 mN·m", 8, H - 8);
    ctx.fillText("x", cx + R + 4, cy + 4);
    ctx.fillText("y", cx - 3, cy - R - 4);
    // shear force: arrow from the centre
    arrow(ctx, cx, cy, cx + R * fx / shearScale, cy - R * fy / shearScale, "rgb(255,170,40)", 3);
    // twist Mz: an arc, its sweep in proportion (full circle = 10 mN m)
    if (Math.abs(mz) > 1e-6) {
      const sweep = Math.max(-1.9 * Math.PI, Math.min(1.9 * Math.PI, (mz / 0.01) * 2 * Math.PI));
      ctx.strokeStyle = "rgb(120,200,255)";
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.arc(cx, cy, 0.3 * R, 0, -sweep, sweep > 0);
      ctx.stroke();
      const end = -sweep, ex = cx + 0.3 * R * Math.cos(end), ey = cy + 0.3 * R * Math.sin(end);
      const t = sweep > 0 ? end - Math.PI / 2 : end + Math.PI / 2;
      arrow(ctx, ex - 6 * Math.cos(t), ey - 6 * Math.sin(t), ex, ey, "rgb(120,200,255)", 2);
    }
    // normal force: a bar on the right, pressing in is up
    const bx = W - 26, bh = R, by = cy;
    ctx.strokeStyle = "#555";
    ctx.strokeRect(bx, by - bh, 14, 2 * bh);
    ctx.fillStyle = normal >= 0 ? "rgb(60,200,120)" : "rgb(230,80,80)";
    const len = bh * Math.max(-1, Math.min(1, normal / normalScale));
    ctx.fillRect(bx, len >= 0 ? by - len : by, 14, Math.abs(len));
    ctx.fillStyle = "#999";
    ctx.fillText("Fn", bx - 2, by + bh + 14);
    ctx.fillText(`${normalScale} N`, bx - 14, by - bh - 6);
    setText("normal-force", normal.toFixed(3));
    setText("shear-force", `${fx.toFixed(3)}, ${fy.toFixed(3)}`);
    setText("moment", `${(1e3 * mx).toFixed(2)}, ${(1e3 * my).toFixed(2)}, ${(1e3 * mz).toFixed(2)}`);
  }

  function drawContact(c) {
    if (!c) {
      for (const id of ["in-contact", "area", "centroid", "max-depth", "peak-pressure", "regions"])
        setText(id, "–");
      return;
    }
    setText("in-contact", c.in_contact ? "yes" : "no");
    setText("area", fmt(c.area * 1e6, 1));
    setText("centroid", `${fmt(c.centroid[0] * 1e3, 2)}, ${fmt(c.centroid[1] * 1e3, 2)}`);
    setText("max-depth", fmt(c.max_depth * 1e6, 0));
    setText("peak-pressure", fmt(c.peak_pressure / 1e3, 1));
    setText("regions", c.regions.length
      ? c.regions.map((r) => `${r.force.toFixed(2)} N`).join(", ") : "none");
  }

  // ------------------------------------------------------------------ slip

  function setBadge(text, kind) {
    setText("slip-state", text);
    const badge = $("slip-state"), name = "badge " + kind;
    if (badge.className !== name) badge.className = name;
  }

  function drawSlip(h) {
    const s = h.slip, canvas = $("slip-direction");
    if (canvas.hidden !== !s) canvas.hidden = !s;
    if (!s) {
      setBadge(state.hello && state.hello.slip ? "no slip message" : "not published", "");
      for (const id of ["stick-ratio", "slip-margin", "friction"]) setText(id, "–");
      state.slipKey = null;
      return;
    }
    setBadge(s.state_name, s.state_name.replace(/ /g, "-"));
    setText("stick-ratio", s.stick_ratio === null ? "–" : `${(100 * s.stick_ratio).toFixed(0)} %`);
    setText("slip-margin", s.slip_margin === null ? "–" : `${(100 * s.slip_margin).toFixed(0)} %`);
    setText("friction", fmt(s.friction_coefficient, 2));
    // the arrow: redrawn only when it moved (to a pixel's worth of its 35 px length)
    const [dx, dy] = s.direction, c = canvas.width / 2;
    const moving = Math.hypot(dx, dy) > 1e-6;
    const key = moving ? `${Math.round(35 * dx)} ${Math.round(35 * dy)}` : "still";
    if (key === state.slipKey) return;
    state.slipKey = key;
    const ctx = ctx2d("slip-direction");
    ctx.fillStyle = "#111";
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    if (moving) arrow(ctx, c, c, c + 35 * dx, c - 35 * dy, "rgb(255,120,120)", 3);
  }

  // ------------------------------------------------------------------ stream figures

  function drawStats(h) {
    const now = performance.now();
    if (now - state.statsAt >= STATS_PERIOD_MS) {  // figures over seconds: twice a second
      state.statsAt = now;
      const st = h.stats || {};
      setText("camera-hz", fmt(st.camera_hz, 1));
      setText("decoded-hz", fmt(st.decoded_hz, 1));
      const n = state.shown.length;
      const hz = n > 1 ? (n - 1) / ((state.shown[n - 1] - state.shown[0]) / 1000) : null;
      setText("shown-hz", fmt(hz, 1));
      setText("latency", st.latency_ms === null || st.latency_ms === undefined ? "–"
        : `${st.latency_ms.toFixed(0)}, ${st.latency_p90_ms.toFixed(0)}`);
      setText("drops", st.dropped_total === undefined ? "–"
        : `${st.dropped_10s} in 10 s, ${st.dropped_total} in all`);
      setText("pages", h.pages === undefined ? "–" : String(h.pages));
    }
    const diagKey = h.diagnostics ? JSON.stringify(h.diagnostics) : null;
    if (diagKey !== null && diagKey !== state.diagKey) {  // the list: only when it changed
      state.diagKey = diagKey;
      const list = $("diagnostics");
      list.replaceChildren(...h.diagnostics.map((d) => {
        const li = document.createElement("li"), level = document.createElement("span");
        level.className = "level " + d.level;
        level.textContent = d.level;
        li.append(level, ` ${d.name}: ${d.message}`);
        return li;
      }));
    }
    showErrors(h.errors || []);
  }

  function showErrors(errors) {
    const key = JSON.stringify(errors);
    if (key === state.errorsKey) return;
    state.errorsKey = key;
    $("errors").replaceChildren(...errors.map((e) => {
      const li = document.createElement("li");
      li.textContent = e;
      return li;
    }));
  }

  // ------------------------------------------------------------------ a recorded bag

  function setupBag(hello) {
    $("bag-panel").hidden = false;
    const slider = $("slider");
    slider.max = String(Math.max(0, hello.frames - 1));
    slider.oninput = () => { stopPlaying(); send({ type: "seek", index: Number(slider.value) }); };
    $("play").onclick = () => {
      if (state.playing) { stopPlaying(); return; }
      $("play").textContent = "pause";
      state.playing = setInterval(() => {
        const next = (Number(slider.value) + 1) % hello.frames;
        slider.value = String(next);
        send({ type: "seek", index: next });
      }, 1000 / Math.max(hello.rate || 10, 1));
    };
  }

  function stopPlaying() {
    if (state.playing) clearInterval(state.playing);
    state.playing = null;
    $("play").textContent = "play";
  }

  function showBagPosition(bag) {
    setText("bag-position", `frame ${bag.index + 1} of ${bag.count}, t = ${bag.time_s.toFixed(2)} s`);
    if (!state.playing && document.activeElement !== $("slider")) $("slider").value = String(bag.index);
  }

  $("map-kind").onchange = (ev) => { state.mapKind = ev.target.value; };
  connect();
})();
