// The section explorer (/explore): draws a section plane, posts clicks to /v1/explore and draws the
// crossings the service streams back (polled), one colour per orbit; shift-click: the periodic orbit.
"use strict";
(() => {
  const $ = (id) => document.getElementById(id);
  const canvas = $("plane");
  const ctx = canvas.getContext("2d");
  const MARGIN = { left: 78, right: 16, top: 14, bottom: 52 };
  const COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf",
    "#bcbd22", "#7f7f7f"];
  const POLL_MS = 80;
  let plane = null;      // {ranges, coordinate_names, units, body}
  let orbits = [];       // {colour, points, seed, item, text}
  let stars = [];        // {points, colour}
  let drawn = 0;

  function say(text, error) {
    const el = $("status");
    el.textContent = text;
    el.classList.toggle("error", Boolean(error));
  }

  async function api(path, body) {
    const options = body === undefined ? {} : {
      method: "POST", headers: { "content-type": "application/json" }, body: JSON.stringify(body) };
    const response = await fetch(path, options);
    const data = await response.json();
    if (!response.ok) {
      const fields = (data.errors || []).map((e) => `${e.field}: ${e.reason}`).join("; ");
      throw new Error(fields || data.detail || data.title || String(response.status));
    }
    return data;
  }

  function request() {
    let system, level;
    try { system = JSON.parse($("system").value); } catch (e) { throw new Error(`system: not JSON (${e.message})`); }
    try { level = JSON.parse($("level").value); } catch (e) { throw new Error(`level: not JSON (${e.message})`); }
    return { system, section: { surface: $("surface").value.trim(), value: Number($("value").value),
      direction: $("direction").value, coordinates: [$("coord0").value.trim(), $("coord1").value.trim()], level } };
  }

  async function loadDefaults() {
    const [kind, potential] = $("kind").value.split("|");
    const d = await api(`/v1/explore/defaults?kind=${encodeURIComponent(kind)}&potential=${encodeURIComponent(potential)}`);
    $("system").value = JSON.stringify(d.system);
    if (d.section) {
      $("surface").value = d.section.surface;
      $("value").value = d.section.value;
      $("direction").value = d.section.direction;
      $("coord0").value = d.section.coordinates[0];
      $("coord1").value = d.section.coordinates[1];
      $("level").value = JSON.stringify(d.section.level);
      await drawPlane();
    } else {
      say("No default plane for this system: fill in a section, its coordinates and a level, then draw the plane.");
    }
  }

  async function drawPlane() {
    const body = request();
    say("Drawing the plane (the level's extent from states sampled on it) …");
    const d = await api("/v1/explore/plane", body);
    plane = { ...d, body };
    clearOrbits();
    canvas.dataset.ready = "1";
    const [a, b] = d.coordinate_names;
    say(`Click inside the plane (${a}, ${b}) to draw the orbit through the point; shift-click for a periodic orbit.`);
  }

  function clearOrbits() {
    orbits = [];
    stars = [];
    drawn = 0;
    canvas.dataset.points = "0";
    $("orbits").replaceChildren();
    redraw();
  }

  const box = () => ({ x0: MARGIN.left, x1: canvas.width - MARGIN.right, y0: MARGIN.top,
    y1: canvas.height - MARGIN.bottom });

  function pixelOf(u, v) {
    const b = box(), [[u0, u1], [v0, v1]] = plane.ranges;
    return [b.x0 + (u - u0) / (u1 - u0) * (b.x1 - b.x0), b.y1 - (v - v0) / (v1 - v0) * (b.y1 - b.y0)];
  }

  function pointAt(x, y) {
    const b = box(), [[u0, u1], [v0, v1]] = plane.ranges;
    return [u0 + (x - b.x0) / (b.x1 - b.x0) * (u1 - u0), v0 + (b.y1 - y) / (b.y1 - b.y0) * (v1 - v0)];
  }

  function label(name) {
    const unit = plane.units[name] || plane.units[name.replace(/\d+$/, "")];
    return unit ? `${name} [${unit}]` : name;
  }

  function ticks(lo, hi, n) {
    const step = Math.pow(10, Math.floor(Math.log10((hi - lo) / n)));
    const nice = [1, 2, 5, 10].map((m) => m * step).find((s) => (hi - lo) / s <= n) || step * 10;
    const out = [];
    for (let t = Math.ceil(lo / nice) * nice; t <= hi + 1e-12 * Math.abs(hi); t += nice) out.push(t);
    return out;
  }

  function redraw() {
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    if (!plane) return;
    const b = box();
    ctx.fillStyle = "#fff";
    ctx.fillRect(b.x0, b.y0, b.x1 - b.x0, b.y1 - b.y0);
    ctx.strokeStyle = "#57606a";
    ctx.strokeRect(b.x0, b.y0, b.x1 - b.x0, b.y1 - b.y0);
    ctx.fillStyle = "#1f2328";
    ctx.font = "12px system-ui, sans-serif";
    const [[u0, u1], [v0, v1]] = plane.ranges;
    ctx.textAlign = "center";
    for (const t of ticks(u0, u1, 6)) {
      const [x] = pixelOf(t, v0);
      ctx.fillText(Number(t.toPrecision(6)).toString(), x, b.y1 + 16);
      ctx.beginPath(); ctx.moveTo(x, b.y1); ctx.lineTo(x, b.y1 + 5); ctx.stroke();
    }
    ctx.textAlign = "right";
    for (const t of ticks(v0, v1, 8)) {
      const [, y] = pixelOf(u0, t);
      ctx.fillText(Number(t.toPrecision(6)).toString(), b.x0 - 8, y + 4);
      ctx.beginPath(); ctx.moveTo(b.x0 - 5, y); ctx.lineTo(b.x0, y); ctx.stroke();
    }
    ctx.textAlign = "center";
    ctx.fillText(label(plane.coordinate_names[0]), (b.x0 + b.x1) / 2, canvas.height - 12);
    ctx.save();
    ctx.translate(16, (b.y0 + b.y1) / 2);
    ctx.rotate(-Math.PI / 2);
    ctx.fillText(label(plane.coordinate_names[1]), 0, 0);
    ctx.restore();
    drawn = 0;
    for (const o of orbits) dots(o.points, o.colour);
    for (const s of stars) star(s.points, s.colour);
  }

  function dots(points, colour) {
    ctx.fillStyle = colour;
    for (const [u, v] of points) {
      const [x, y] = pixelOf(u, v);
      ctx.fillRect(x - 1, y - 1, 2, 2);
    }
    drawn += points.length;
    canvas.dataset.points = String(drawn);
  }

  function star(points, colour) {
    for (const [u, v] of points) {
      const [x, y] = pixelOf(u, v);
      ctx.beginPath();
      for (let i = 0; i < 10; i++) {
        const r = i % 2 ? 4 : 10, a = -Math.PI / 2 + i * Math.PI / 5;
        ctx.lineTo(x + r * Math.cos(a), y + r * Math.sin(a));
      }
      ctx.closePath();
      ctx.fillStyle = colour;
      ctx.strokeStyle = "#000";
      ctx.fill();
      ctx.stroke();
    }
  }

  function listItem(colour, text) {
    const item = document.createElement("li");
    const swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.backgroundColor = colour;  // CSSOM, not a style attribute: allowed by style-src 'self'
    item.append(swatch, document.createTextNode(text));
    $("orbits").append(item);
    return item;
  }

  const fmt = (x) => Number(x).toPrecision(5);

  // The clicked orbit as a job request (POST /v1/jobs): the same system, the state the click was completed to,
  // t_final, and the section as a poincare block; a job run from it gives these crossings with its evidence.
  function jobOf(body, initialState) {
    const s = body.section;
    return { system: body.system, initial_state: initialState, t_final: body.t_final, samples: 2001,
      poincare: { surface: s.surface, value: s.value, direction: s.direction, coordinates: s.coordinates,
        max_points: body.max_points } };
  }

  // "copy as request": the JSON shown under the orbit's line, and a button that copies it
  function asRequest(item, job) {
    const details = document.createElement("details");
    const summary = document.createElement("summary");
    summary.textContent = "as a job request (JSON for POST /v1/jobs)";
    const copy = document.createElement("button");
    copy.type = "button";
    copy.className = "copy";
    copy.textContent = "copy";
    const text = JSON.stringify(job, null, 1);
    copy.addEventListener("click", () => {
      navigator.clipboard.writeText(text).then(() => { copy.textContent = "copied"; },
        () => { copy.textContent = "select the text to copy"; });
    });
    const pre = document.createElement("pre");
    pre.className = "request";
    pre.textContent = text;
    details.append(summary, copy, pre);
    item.append(details);
  }

  async function orbit(u, v) {
    const colour = COLOURS[orbits.length % COLOURS.length];
    const body = { ...plane.body, point: [u, v], t_final: Number($("t_final").value),
      max_points: Number($("max_points").value) };
    const accepted = await api("/v1/explore/orbits", body);
    const item = listItem(colour, "");
    const o = { colour, points: [], seed: [u, v], item, text: item.lastChild };
    orbits.push(o);
    asRequest(item, jobOf(body, accepted.initial_state));
    const started = performance.now();
    const poll = async () => {
      const d = await api(`/v1/explore/orbits/${accepted.id}?since=${o.points.length}`);
      o.points.push(...d.points);
      dots(d.points, colour);
      const seconds = ((performance.now() - started) / 1000).toFixed(2);
      o.text.textContent = ` from (${fmt(u)}, ${fmt(v)}): ${o.points.length} crossings, t = ` +
        `${fmt(d.t_reached)} s${d.done ? "" : " …"} (${seconds} s)` + (accepted.branches > 1
        ? `; ${accepted.branches} states of the level cross here, the first taken` : "") +
        (d.error ? `; failed: ${d.error}` : "");
      if (!d.done) setTimeout(() => poll().catch((e) => say(e.message, true)), POLL_MS);
    };
    await poll();
  }

  async function periodic(u, v) {
    const period = Number($("period").value) || 1;
    say(`Looking for a period-${period} orbit near (${fmt(u)}, ${fmt(v)}) …`);
    const body = { ...plane.body, point: [u, v], period, t_final: Number($("t_final").value) };
    const o = await api("/v1/explore/periodic-orbit", body);
    const colour = COLOURS[(orbits.length + stars.length) % COLOURS.length];
    if (o.status === "not_found") {
      listItem("#ffffff", ` no period-${period} orbit from (${fmt(u)}, ${fmt(v)}): ${o.reason}`);
      say("No periodic orbit closed from that point; try another point or period.");
      return;
    }
    stars.push({ points: o.points, colour });
    star(o.points, colour);
    const mu = o.section_multipliers.map((m) => m.im ? `${fmt(m.re)} ${m.im > 0 ? "+" : "−"} ${fmt(Math.abs(m.im))}i`
      : fmt(m.re)).join(", ");
    listItem(colour, ` ★ period-${period} orbit (${o.status}): T = ${fmt(o.period_t)} s, ${o.stability}, ` +
      `trace ${o.trace === null ? "–" : fmt(o.trace)}, multipliers ${mu}; closes to ` +
      `${Number(o.residual_independent).toExponential(1)} (DOP853)`);
    say(o.status === "degenerate" ? o.reason : `Found: ${o.stability} period-${period} orbit, T = ${fmt(o.period_t)} s.`);
  }

  // Drag a box: a chaos map of it (an ensemble whose grid is the box), linked once accepted.
  const MAP_SHAPE = [16, 16];
  const MAP_T_FINAL = 200;
  let drag = null;       // {x, y, x2, y2}: canvas pixels while the button is down
  let dragged = false;   // the click that ends a drag draws no orbit

  function canvasXY(event) {
    const rect = canvas.getBoundingClientRect();  // the border is outside the drawing
    return [(event.clientX - rect.left - canvas.clientLeft) * canvas.width / canvas.clientWidth,
      (event.clientY - rect.top - canvas.clientTop) * canvas.height / canvas.clientHeight];
  }

  async function boxMap(d) {
    const [ua, va] = pointAt(d.x, d.y), [ub, vb] = pointAt(d.x2, d.y2);
    const ranges = [[Math.min(ua, ub), Math.max(ua, ub)], [Math.min(va, vb), Math.max(va, vb)]];
    const s = plane.body.section;
    const body = { system: plane.body.system, t_final: Math.min(Number($("t_final").value), MAP_T_FINAL),
      indicators: ["megno"], members: { grid: { surface: s.surface, value: s.value, direction: s.direction,
        coordinates: s.coordinates, level: s.level, shape: MAP_SHAPE, ranges } } };
    say("Submitting a chaos map of the box …");
    const accepted = await api("/v1/ensembles", body);
    const item = listItem("#ffffff", ` ▦ chaos map of ${s.coordinates[0]} ${fmt(ranges[0][0])} .. ${fmt(ranges[0][1])}, ` +
      `${s.coordinates[1]} ${fmt(ranges[1][0])} .. ${fmt(ranges[1][1])} (${MAP_SHAPE.join(" × ")} cells, ` +
      `t = ${body.t_final} s): `);
    const link = document.createElement("a");
    link.href = `${accepted.location}/page`;
    link.className = "map-link";
    link.textContent = "its page";
    item.append(link);
    say("The map runs as an ensemble: its page fills in as its cells finish.");
  }

  canvas.addEventListener("mousedown", (event) => {
    if (!plane || event.shiftKey || event.button !== 0) return;
    const [x, y] = canvasXY(event);
    drag = { x, y, x2: x, y2: y };
    dragged = false;
  });
  canvas.addEventListener("mousemove", (event) => {
    if (!drag) return;
    [drag.x2, drag.y2] = canvasXY(event);
    if (Math.abs(drag.x2 - drag.x) + Math.abs(drag.y2 - drag.y) < 8) return;
    dragged = true;
    redraw();
    ctx.setLineDash([5, 3]);
    ctx.strokeStyle = "#d62728";
    ctx.strokeRect(drag.x, drag.y, drag.x2 - drag.x, drag.y2 - drag.y);
    ctx.setLineDash([]);
  });
  window.addEventListener("mouseup", () => {
    const d = drag;
    drag = null;
    if (d && dragged) {
      redraw();
      boxMap(d).catch((e) => say(e.message, true));
    }
  });

  canvas.addEventListener("click", (event) => {
    if (!plane) return;
    if (dragged) {  // the end of a drag, not a click
      dragged = false;
      return;
    }
    const [x, y] = canvasXY(event);
    const b = box();
    if (x < b.x0 || x > b.x1 || y < b.y0 || y > b.y1) return;
    const [u, v] = pointAt(x, y);
    (event.shiftKey ? periodic(u, v) : orbit(u, v)).catch((e) => say(e.message, true));
  });
  $("kind").addEventListener("change", () => loadDefaults().catch((e) => say(e.message, true)));
  $("draw").addEventListener("click", () => drawPlane().catch((e) => say(e.message, true)));
  $("clear").addEventListener("click", clearOrbits);
  // for the tests and the curious: where a point of the plane is on the canvas
  window.explorer = { pixelOf: (u, v) => pixelOf(u, v), plane: () => plane };
  loadDefaults().catch((e) => say(e.message, true));
})();
