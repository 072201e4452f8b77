/* zkzap web: the ZK console page. */
"use strict";
(() => {
  const { $, el, fmt, clock, setText, setClass } = Z;
  const latest = {};              // every status field's latest value
  let engine = { controlling: false };
  let mode = "throttle";
  let limitsByField = {};         // field -> [condition text]
  let lastSample = 0;

  // -- gauges and tiles ----------------------------------------------------------------------
  const GAUGES = [
    { key: "rpm", name: "RPM", unit: "rpm", max: () => latest.max_rpm || 160000, digits: 0 },
    { key: "egt_c", name: "EGT", unit: "°C", max: () => 1000, digits: 0 },
    { key: "thrust_kg", name: "Thrust", unit: "kg", max: () => Math.max(5, Math.ceil((maxSeen.thrust_kg || 0) * 1.25)), digits: 1 },
    { key: "throttle_pct", name: "Throttle", unit: "%", max: () => 100, digits: 0 },
  ];
  const TILES = [
    { key: "fuel_flow_l_min", name: "Fuel flow", unit: "L/min", digits: 2 },
    { key: "fuel_used_l", name: "Fuel used", unit: "L", digits: 1 },
    { key: "power_voltage_v", name: "Power", unit: "V", digits: 1 },
    { key: "pump_voltage_v", name: "Pump", unit: "V", digits: 1 },
    { key: "radio_voltage_v", name: "Radio", unit: "V", digits: 1 },
    { key: "current_a", name: "Current", unit: "A", digits: 1 },
    { key: "ecu_temp_c", name: "ECU temp", unit: "°C", digits: 0 },
    { key: "max_rpm", name: "Max rpm", unit: "", digits: 0 },
    { key: "idle_rpm", name: "Idle rpm", unit: "", digits: 0 },
  ];
  const maxSeen = {};
  const A0 = 150, SWEEP = 240, R = 80, CX = 100, CY = 100;
  const pt = (deg, r = R) => [CX + r * Math.cos(deg * Math.PI / 180), CY + r * Math.sin(deg * Math.PI / 180)];
  const arc = (a, b) => { const [x0, y0] = pt(a), [x1, y1] = pt(b);
    return `M${x0.toFixed(1)} ${y0.toFixed(1)} A${R} ${R} 0 ${b - a > 180 ? 1 : 0} 1 ${x1.toFixed(1)} ${y1.toFixed(1)}`; };
  const SVG = "http://www.w3.org/2000/svg";
  const svg = (tag, attrs, text) => { const e = document.createElementNS(SVG, tag); for (const k in attrs) e.setAttribute(k, attrs[k]);
    if (text !== undefined) e.textContent = text; return e; };

  const gauges = {}, tiles = {};
  function buildGauges() {
    const box = $("#gauges");
    for (const g of GAUGES) {
      const s = svg("svg", { viewBox: "0 0 200 166", role: "img", "aria-label": g.name });
      s.append(svg("path", { d: arc(A0, A0 + SWEEP), stroke: "#2c3a48", "stroke-width": 14, fill: "none", "stroke-linecap": "round" }));
      const val = svg("path", { d: arc(A0, A0 + 0.1), stroke: "#4aa3ff", "stroke-width": 14, fill: "none", "stroke-linecap": "round" });
      const band = svg("path", { d: "", stroke: "#f2b134", "stroke-width": 4, fill: "none", class: "band" });
      const mark = svg("path", { d: "", stroke: "#ff5d5d", "stroke-width": 4, fill: "none", class: "mark" });
      const v = svg("text", { x: CX, y: CY + 8, "text-anchor": "middle", class: "gv" }, "–");
      const u = svg("text", { x: CX, y: CY + 32, "text-anchor": "middle", class: "gu" }, g.unit);
      const lo = svg("text", { x: pt(A0)[0], y: CY + 62, "text-anchor": "middle", class: "gs" }, "0");
      const hi = svg("text", { x: pt(A0 + SWEEP)[0], y: CY + 62, "text-anchor": "middle", class: "gs" }, "");
      s.append(val, band, mark, v, u, lo, hi);
      const cell = el("div", { class: "gauge", id: "g-" + g.key }, s, el("div", { class: "n", text: g.name }));
      box.append(cell);
      gauges[g.key] = { g, cell, val, band, mark, v, hi };
    }
    const t = el("div", { class: "tiles" });
    for (const d of TILES) {
      const v = el("span", { class: "num", text: "–" });
      const cell = el("div", { class: "tile", id: "t-" + d.key }, el("div", { class: "n", text: d.name }), el("div", { class: "v" }, v, el("small", { text: d.unit })));
      t.append(cell);
      tiles[d.key] = { d, cell, v };
    }
    box.append(t);
  }
  const tick = (value, max) => {
    const f = Math.max(0, Math.min(1, value / max));
    const a = A0 + SWEEP * f, [x0, y0] = [CX + (R - 11) * Math.cos(a * Math.PI / 180), CY + (R - 11) * Math.sin(a * Math.PI / 180)];
    const [x1, y1] = [CX + (R + 11) * Math.cos(a * Math.PI / 180), CY + (R + 11) * Math.sin(a * Math.PI / 180)];
    return `M${x0.toFixed(1)} ${y0.toFixed(1)} L${x1.toFixed(1)} ${y1.toFixed(1)}`;
  };
  // a rate limit (FIELD/s) is no level of the field: not drawn on its gauge or plot
  const fieldLimits = (key) => Z.hello && limitsByField[key] ? Z.hello.limits.filter(l => l.field === key && !l.rate) : [];
  // the limit's tick (red) and its warning band's start (amber), for every limit of the field
  const limitMark = (key, max) => fieldLimits(key).map(c => tick(c.threshold, max)).join(" ");
  const bandMark = (key, max) => fieldLimits(key).filter(c => c.warn !== null && c.warn !== undefined).map(c => tick(c.warn, max)).join(" ");
  const levels = {};              // field -> "", "warn", "bad" from the limits
  function paintGauges() {
    for (const key in gauges) {
      const { g, cell, val, band, mark, v, hi } = gauges[key];
      const x = latest[key], max = g.max(), lvl = levels[key] || "";
      const sig = `${x}|${max}|${lvl}`;
      if (gauges[key].sig === sig) continue;
      gauges[key].sig = sig;
      const f = x === undefined || x === null ? 0 : Math.max(0, Math.min(1, x / max));
      val.setAttribute("d", arc(A0, A0 + Math.max(0.1, SWEEP * f)));
      val.setAttribute("stroke", lvl === "bad" ? "#ff5d5d" : lvl === "warn" ? "#f2b134" : "#4aa3ff");
      mark.setAttribute("d", limitMark(key, max));
      band.setAttribute("d", bandMark(key, max));
      const text = fmt(x, g.digits);
      setText(v, text);
      v.style.fontSize = text.length > 6 ? "28px" : "";
      setText(hi, max >= 10000 ? `${fmt(max / 1000)}k` : fmt(max));
      setClass(cell, "gauge " + lvl);
    }
    for (const key in tiles) {
      const { d, cell, v } = tiles[key];
      setText(v, fmt(latest[key], d.digits));
      setClass(cell, "tile " + (levels[key] || ""));
    }
  }

  // -- engine state --------------------------------------------------------------------------
  const RUN = new Set([6, 7, 8, 9, 10, 11]), START = new Set([2, 3, 4, 5, 13]), TEST = new Set([14, 15, 16, 17, 18, 19]);
  function paintState() {
    const s = latest.engine_state;
    const st = $("#state");
    setText(st, latest.engine_state_name ?? "–");
    setClass(st, "state " + (s === undefined ? "" : RUN.has(s) ? "run" : START.has(s) ? "start" : s === 12 ? "cool" : TEST.has(s) ? "test" : "off"));
    const e = $("#error");
    if (latest.error_code) { setText(e, `ECU error ${latest.error_code}: ${latest.error_name}`); setClass(e, "error bad"); }
    else { setText(e, "no ECU error"); setClass(e, "error"); }
    setText($("#swst"), latest.sw_state_name ? `switch: ${latest.sw_state_name}` : "");
  }
  function paintEngine() {
    const c = $("#command");
    if (engine.controlling) {
      const cmd = engine.command;
      const what = cmd.mode === "rpm" ? `RPM mode, target ${fmt(cmd.rpm)} rpm` : `throttle ${fmt(cmd.throttle, 1)} %`;
      c.textContent = `Running under this console: ${what} — by ${engine.by}, since ${clock(engine.since)}`;
      c.className = "command on";
    } else {
      c.textContent = "Monitoring: this console does not run the engine.";
      c.className = "command";
    }
    const e = engine.ended;
    $("#ended").textContent = e ? `Last run ended ${clock(e.t)}: ${e.why}` + (e.sent ? ` — sent ${e.sent}` : "") : "";
    $("#start").dataset.off = engine.controlling ? "1" : "0";
    Z.renderControl();
    if (engine.controlling && engine.command && !dragging) syncInputs(engine.command);
  }

  // -- controls ------------------------------------------------------------------------------
  let dragging = false;
  function setMode(m) {
    mode = m;
    $("#mode-throttle").classList.toggle("on", m === "throttle");
    $("#mode-rpm").classList.toggle("on", m === "rpm");
    $("#sp-throttle").hidden = m !== "throttle";
    $("#sp-rpm").hidden = m !== "rpm";
    if (engine.controlling) sendSet();
  }
  function syncInputs(cmd) {
    if (cmd.mode === "throttle") { $("#throttle").value = cmd.throttle; $("#throttle-range").value = cmd.throttle; }
    else { $("#rpm").value = cmd.rpm; $("#rpm-range").value = cmd.rpm; }
    if (cmd.mode !== mode) { mode = cmd.mode; setModeButtons(); }
  }
  function setModeButtons() {
    $("#mode-throttle").classList.toggle("on", mode === "throttle");
    $("#mode-rpm").classList.toggle("on", mode === "rpm");
    $("#sp-throttle").hidden = mode !== "throttle"; $("#sp-rpm").hidden = mode !== "rpm";
  }
  const setpoint = () => mode === "rpm" ? { mode, rpm: Number($("#rpm").value) } : { mode, throttle: Number($("#throttle").value) };
  const sendSet = Z.throttle(() => { if (engine.controlling) Z.send("set", setpoint()); }, 120);
  function bind(range, num) {
    range.addEventListener("input", () => { num.value = range.value; dragging = true; sendSet(); });
    range.addEventListener("change", () => { dragging = false; sendSet(); });
    num.addEventListener("change", () => { range.value = num.value; sendSet(); });
  }

  // -- plots ---------------------------------------------------------------------------------
  let plots = null;
  // the plots a limit's field is drawn in: its limit (red, dashed) and warning band (amber, dotted)
  // are lines there
  const PLOT_OF = { rpm: "rpm", egt_c: "egt", thrust_kg: "thrust", fuel_flow_l_min: "fuel", power_voltage_v: "volts",
                    pump_voltage_v: "volts", radio_voltage_v: "volts", current_a: "current" };
  const lines = {};                // plot -> [threshold values], pushed with every point
  function limitSeries(name) {
    const out = [];
    lines[name] = [];
    for (const c of (Z.hello && Z.hello.limits) || []) {
      if (PLOT_OF[c.field] !== name || c.rate) continue;
      out.push({ label: `limit ${c.text}`, color: "#ff5d5d", dash: [6, 4], width: 1.2 });
      lines[name].push(c.threshold);
      if (c.warn !== null && c.warn !== undefined) {
        out.push({ label: "warning", color: "#f2b134", dash: [2, 4], width: 1.2 });
        lines[name].push(c.warn);
      }
    }
    return out;
  }
  function buildPlots() {
    const box = $("#plots");
    plots = {};
    plots.rpm = new Z.Plot(box, "RPM", [{ label: "rpm", color: "#4aa3ff" }, { label: "target", color: "#f2b134" }, ...limitSeries("rpm")]);
    plots.egt = new Z.Plot(box, "EGT", [{ label: "EGT °C", color: "#ff7b54" }, ...limitSeries("egt")]);
    plots.thrust = new Z.Plot(box, "Thrust and throttle", [{ label: "thrust kg", color: "#3fcf7a", digits: 1 },
      { label: "throttle %", color: "#c59bff", scale: "r" }, ...limitSeries("thrust")], { right: true, rightRange: [0, 100], digits: 1 });
    plots.fuel = new Z.Plot(box, "Fuel flow", [{ label: "L/min", color: "#57c7e6", digits: 2 }, ...limitSeries("fuel")], { digits: 2 });
    plots.volts = new Z.Plot(box, "Voltages", [{ label: "power V", color: "#f2b134", digits: 1 },
      { label: "pump V", color: "#3fcf7a", digits: 1 }, { label: "radio V", color: "#8b9bab", digits: 1 }, ...limitSeries("volts")], { digits: 1 });
    plots.current = new Z.Plot(box, "Current", [{ label: "A", color: "#ff5d5d", digits: 1 }, ...limitSeries("current")], { digits: 1 });
    Z.onFrame(() => { paintGauges(); paintState(); });
  }
  const put = (name, t, values) => plots[name].push(t, values.concat(lines[name]));
  function plotSample(it) {
    if (!plots) return;
    const t = it.w / 1000;
    const target = engine.controlling && engine.command && engine.command.mode === "rpm" ? engine.command.rpm : null;
    put("rpm", t, [it.rpm, target]);
    switch (it.id) {
      case 1: put("egt", t, [it.egt_c]); break;
      case 2: put("volts", t, [it.power_voltage_v, it.pump_voltage_v, it.radio_voltage_v]); break;
      case 3: put("thrust", t, [null, it.throttle_pct]); break;
      case 4: put("thrust", t, [it.thrust_kg, null]); put("current", t, [it.current_a]); break;
      case 7: put("fuel", t, [it.fuel_flow_l_min]); break;
    }
  }

  function take(it, live) {
    for (const k in it) if (k !== "w" && k !== "t" && k !== "id" && k !== "stale" && k !== "stale_ids") latest[k] = it[k];
    for (const k of ["thrust_kg"]) if (it[k] !== undefined && it[k] > (maxSeen[k] || 0)) maxSeen[k] = it[k];
    // the limits of the fields this frame carries
    for (const field in limitsByField) {
      if (!(field in it)) continue;
      const texts = limitsByField[field];
      levels[field] = texts.some(x => (it.limit || []).includes(x)) ? "bad" : texts.some(x => (it.warnings || []).includes(x)) ? "warn" : "";
    }
    plotSample(it);
    if (live) { lastSample = it.w; Z.sawSample(it.w); }
  }

  // -- limits --------------------------------------------------------------------------------
  function paintLimits(summary) {
    if (!Z.hello || !Z.hello.limits.length) return;
    const box = $("#limits");
    box.className = "";
    box.replaceChildren(...Z.hello.limits.map((c, i) => {
      const s = summary ? summary[i] : null;
      const v = s ? s.verdict : "unchecked";
      const cls = v === "violated" ? "bad" : v === "warn" ? "warn" : v === "ok" ? "ok" : "";
      const ext = s && s.extreme !== null ? `extreme ${fmt(s.extreme, 1)}` : "not checked yet";
      return el("div", { class: "limit" }, el("code", { text: c.text }), el("span", { class: "dim num", text: ext }),
        el("span", { class: "tag " + cls, text: v }));
    }), el("div", { class: "dim small", text: Z.hello.on_limit === "abort"
      ? "A violation while this console runs the engine ends the run with the abort." : "Violations are shown; the engine goes on (--on-limit warn)." }));
  }

  // -- alarms --------------------------------------------------------------------------------
  let alarms = { items: [], latched: 0 };
  let beeped = 0, audio = null;
  function beep() {                 // an audible alarm, while one is latched (when the box is ticked)
    if (!$("#audible").checked) return;
    try {
      audio = audio || new (window.AudioContext || window.webkitAudioContext)();
      const o = audio.createOscillator(), g = audio.createGain();
      o.frequency.value = 880; g.gain.value = 0.15; o.connect(g); g.connect(audio.destination);
      o.start(); o.stop(audio.currentTime + 0.25);
    } catch (e) { /* no audio on this machine */ }
  }
  function paintAlarms() {
    const box = $("#alarms");
    const items = alarms.items;
    $("#alarmscard").classList.toggle("latched", alarms.latched > 0);
    $("#ack").disabled = !(alarms.latched > 0 && Z.controlling());
    $("#ack").textContent = alarms.latched > 0 ? `Acknowledge ${alarms.latched}` : "Acknowledge";
    if (!items.length) { box.className = "dim"; box.textContent = "No alarm."; return; }
    box.className = "";
    box.replaceChildren(...items.slice(0, 50).map(a => {
      const state = a.latched ? "LATCHED" : a.level === "warning" ? (a.active ? "warning" : "warning, over") : a.active ? "active, acknowledged" : "acknowledged";
      const row = el("div", { class: `alarm ${a.level}` + (a.latched ? " latched" : ""), "data-id": a.id },
        el("span", { class: "when", text: clock(Date.parse(a.time) / 1000) }),
        el("span", { class: "what", text: a.text }),
        el("span", { class: "tag " + (a.latched ? "bad" : a.level === "warning" ? "warn" : ""), text: state }));
      if (a.acked_by) row.append(el("span", { class: "acked", text: `acknowledged by ${a.acked_by} at ${clock(Date.parse(a.acked_at) / 1000)}` }));
      return row;
    }));
  }
  let interlock = null;
  function paintInterlock(text) {
    if (text !== undefined) interlock = text;
    const i = $("#interlock");
    const said = interlock || (alarms.zero_setpoint ? "After the trip the next start is at setpoint 0." : "");
    setText(i, said);
    setClass(i, "interlock small " + (interlock ? "bad" : "dim"));
  }
  function zeroSetpoint() {         // after a trip the next start begins at setpoint 0
    for (const id of ["#throttle", "#throttle-range", "#rpm", "#rpm-range"]) $(id).value = 0;
  }

  // -- messages ------------------------------------------------------------------------------
  const pct = (arr, p) => { if (!arr.length) return null; const s = arr.slice(-400).sort((a, b) => a - b); return s[Math.min(s.length - 1, Math.floor(p * s.length))]; };
  const handlers = {
    hello(m) {
      limitsByField = {};
      for (const c of m.limits) (limitsByField[c.field] = limitsByField[c.field] || []).push(c.text);
      $("#safety").textContent = `Abort: ${m.abort_text}, out of RPM mode — from every page. The engine also goes to standby when the controlling page closes or is silent for ${m.deadman_s} s, the ECU falls silent for ${m.silence_s} s or reports a new error, or a limit is violated.` + (m.simulated ? "" : " A start asks for confirmation.");
      paintLimits(null);
      if (!plots) buildPlots();       // with the limits' lines (the first hello; a reconnection keeps them)
    },
    history(m) { for (const it of m.items) take(it, false); },
    samples(m) { for (const it of m.items) take(it, true); },
    engine(m) {
      const ended = engine.controlling && !m.controlling;
      engine = m;
      if (ended && alarms.zero_setpoint) zeroSetpoint();     // a run that tripped: back to 0
      paintEngine();
    },
    alarms(m) {
      const more = m.latched > alarms.latched;
      const zero = m.zero_setpoint && !alarms.zero_setpoint;
      alarms = m;
      if (zero && !engine.controlling) zeroSetpoint();
      paintAlarms();
      paintInterlock();
      if (more) beep();
    },
    health(m) {
      const l = $("#link");
      const silent = m.silent_s !== null && m.silent_s > 1;
      if (m.silent_s === null) { l.textContent = "no status frame yet"; l.className = "pill warn"; }
      else if (silent) { l.textContent = `ECU silent ${fmt(m.silent_s, 1)} s`; l.className = "pill bad"; }
      else if (m.stale) { l.textContent = `${fmt(m.frames_per_s)} frames/s · stale IDs ${m.stale_ids.join(",")}`; l.className = "pill warn"; }
      else { l.textContent = `${fmt(m.frames_per_s)} frames/s · protocol v${m.protocol_version}`; l.className = "pill ok"; }
      $("#rate").textContent = latest.status_rate_hz ? `status rate ${latest.status_rate_hz} Hz` : "";
      $("#health").textContent = `frames ${fmt(m.frames)} · CRC errors ${fmt(m.crc_errors)} · skipped bytes ${fmt(m.skipped)}` + (m.version_note ? ` · ${m.version_note}` : "");
      const p50 = pct(Z.stats.latencies, .5), p99 = pct(Z.stats.latencies, .99);
      $("#lat").textContent = p50 === null ? "" : `latency p50 ${fmt(p50)} ms · p99 ${fmt(p99)} ms` + (Z.stats.dropped ? ` · ${Z.stats.dropped} dropped` : "");
      if (m.limits) paintLimits(m.limits);
      paintInterlock(m.interlock);
      if (alarms.latched && Date.now() - beeped > 2000) { beeped = Date.now(); beep(); }
      const mx = latest.max_rpm, idle = latest.idle_rpm;
      if (mx) { $("#rpm-range").max = mx; $("#rpm").max = mx; $("#rpm-limits").textContent = `(${fmt(idle)} – ${fmt(mx)})`; }
      if (idle) $("#rpm-range").min = 0;
    },
    controlchange(c) {
      $("#ctlnote").textContent = c.controlling ? "" : "view only";
      paintAlarms();
      $("#who").textContent = c.controller ? `controlling: ${c.controller.label}` : "nobody controls";
    },
  };

  {
    buildGauges();
    bind($("#throttle-range"), $("#throttle"));
    bind($("#rpm-range"), $("#rpm"));
    $("#mode-throttle").addEventListener("click", () => setMode("throttle"));
    $("#mode-rpm").addEventListener("click", () => setMode("rpm"));
    $("#start").addEventListener("click", async () => {
      const r = await Z.send("start", setpoint());
      if (r) Z.toast("engine start sent", "info");
    });
    $("#stop").addEventListener("click", () => Z.send("stop"));
    $("#ack").addEventListener("click", async () => {
      const r = await Z.send("ack", {});
      if (r && r.acknowledged) Z.toast(`${r.acknowledged.length} alarm${r.acknowledged.length === 1 ? "" : "s"} acknowledged`, "info");
    });
    $("#abort").addEventListener("click", () => Z.send("abort"));
    setInterval(() => {
      if (lastSample && Date.now() - lastSample > 2500) { const l = $("#link"); l.textContent = `no status for ${fmt((Date.now() - lastSample) / 1000, 1)} s`; l.className = "pill bad"; }
    }, 500);
    Z.connect(handlers);
  }
})();
