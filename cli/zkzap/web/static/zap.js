/* zkzap web: the mightyZAP console page. */
"use strict";
(() => {
  const { $, el, fmt, setText } = Z;
  // each bus's scan records and baud rate (one bus: the key ""); an actuator is its bus and ID
  const state = {};
  const S = (bus) => state[bus ?? ""] || (state[bus ?? ""] = { actuators: [], baud: null, failed: null, busy: null });
  const names = () => Z.buses ? Z.buses.map(b => b.name) : [""];
  const keyOf = (bus, id) => `${bus ?? ""}|${id}`;
  // a request for an actuator of ``bus`` (one bus: as it always was)
  const at = (bus, fields) => Z.buses ? { bus, ...fields } : fields;
  let protocol = "ir";            // the chosen bus's protocol family (hello): a Modbus map's addresses are decimal
  const live = {};                // bus|id -> latest sample
  const rows = {};                // bus|id -> row elements
  let plots = null, plotIds = "";
  let regId = null, regInfo = {};
  let busy = null;
  const COLORS = ["#4aa3ff", "#3fcf7a", "#f2b134", "#ff7b54", "#c59bff", "#57c7e6", "#ff5d9e", "#b5e853"];

  // -- each bus's register map (the console's: every range and unit the page shows is its) ---
  const maps = {};                // bus -> {register name: info}; one bus: the key ""
  const regOf = (bus, name) => (maps[bus ?? ""] || {})[name] || {};
  // a register's range as the map gives it: [lo, hi] (the present register's where the goal has none)
  function rangeOf(bus, name, other) {
    const r = regOf(bus, name), o = other ? regOf(bus, other) : {};
    return [r.lo ?? o.lo ?? null, r.hi ?? o.hi ?? null];
  }
  const digitsOf = (r) => r.scale && r.scale < 1 ? Math.round(-Math.log10(r.scale)) : 0;
  // the supply voltage as the map gives it: in its unit (the console scales it), or the raw value,
  // said to be raw, where the map gives no unit
  function voltageOf(bus) {
    const r = regOf(bus, "present-voltage");
    return r.unit ? { unit: r.unit, digits: digitsOf(r) } : { unit: null, digits: 0 };
  }
  Z.voltageOf = voltageOf;
  Z.voltText = (v, vu) => v === null || v === undefined ? "–" : vu.unit ? `${fmt(v, vu.digits)} ${vu.unit}` : `${fmt(v)} (raw)`;
  Z.rangeOf = rangeOf;
  const keepMap = (bus, registers) => { maps[bus ?? ""] = Object.fromEntries((registers || []).map(r => [r.name, r])); };

  // -- the actuator table --------------------------------------------------------------------
  function statusTag(a, s, st) {
    if (st.failed) return el("span", { class: "tag bad", text: "bus failed", title: st.failed });
    if (a.baud !== st.baud) return el("span", { class: "tag warn", text: `at ${a.baud} baud` });
    if (!a.polled) return el("span", { class: "tag warn", text: a.return_mode === 0 ? "mode 0: echo only" : a.status });
    const errs = (s && s.errors && s.errors.length) ? s.errors : a.errors;
    if (errs && errs.length) return el("span", { class: "tag bad", text: errs.join(", ") });
    if (s && s.status === "bad-reply") return el("span", { class: "tag bad", text: "garbled",
      title: "garbled reply: a collision (two actuators answering to one ID) or a line fault" });
    if (s && s.status !== "ok") return el("span", { class: "tag warn", text: s.status });
    return el("span", { class: "tag ok", text: a.status });
  }
  function buildTable() {
    const tb = $("#actuators tbody");
    tb.replaceChildren();
    for (const k in rows) delete rows[k];
    let total = 0;
    names().forEach((bus, k) => {
      const st = S(bus);
      total += st.actuators.length;
      if (Z.buses) tb.append(busHead(bus, k, st));
      for (const a of st.actuators) tb.append(actuatorRow(bus, k, a, st));
    });
    const st = S(names()[0]);
    $("#act-note").textContent = !Z.buses ? (total ? `${total} found · bus at ${st.baud} baud` : "none found yet: scan")
      : `${total} found on ${names().length} buses`;
    Z.renderControl();
  }
  function busInfo(bus) { return (Z.buses || []).find(b => b.name === bus) || {}; }
  // a bus's name where space is short (the plots' keys): a long port given by -p is "bus N"
  function short(bus) { const k = names().indexOf(bus); return bus.length > 14 ? `bus ${k + 1}` : bus; }
  function busHead(bus, k, st) {
    const b = busInfo(bus);
    return el("tr", { class: "bushead", id: `bushead-${k}`, "data-bus": bus },
      el("td", { colspan: 12 }, el("b", { text: short(bus) === bus ? `bus ${bus}` : `${short(bus)}: ${bus}` }), b.port && b.port !== bus ? el("span", { class: "dim", text: ` ${b.port}` }) : "",
        el("span", { class: "tag", text: b.protocol === "modbus" ? "Modbus RTU" : "IR" }),
        el("span", { class: "dim", text: st.failed ? "" : st.actuators.length ? ` ${st.actuators.length} found at ${st.baud} baud` : " none found yet" }),
        st.failed ? el("span", { class: "tag bad", text: "failed", title: st.failed }) : ""));
  }
  function actuatorRow(bus, k, a, st) {
      const id = a.id;
      const sync = el("input", { type: "checkbox", class: "ctl sync", "data-id": id, "data-bus": Z.buses ? bus : null, title: "move with Sync move" });
      const [plo, phi] = rangeOf(bus, "goal-position", "present-position");
      const range = el("input", { type: "range", class: "ctl grow", min: plo, max: phi, value: plo ?? 0, "aria-label": `goal of ID ${id}` });
      const num = el("input", { type: "number", class: "ctl", min: plo, max: phi, value: plo ?? 0, "aria-label": `goal number of ID ${id}` });
      const mover = Z.throttle((p) => Z.send("move", at(bus, { id, position: p })), 60);
      let touched = false;
      range.addEventListener("input", () => { num.value = range.value; touched = true; mover(Number(range.value)); });
      range.addEventListener("change", () => { touched = false; });
      num.addEventListener("change", () => { range.value = num.value; Z.send("move", at(bus, { id, position: Number(num.value) })); });
      const sp = regOf(bus, "goal-speed"), gc = regOf(bus, "goal-current");
      const gspeed = el("input", { type: "number", class: "ctl goal-speed", min: sp.lo, max: sp.hi, placeholder: "speed",
        title: `goal-speed ${sp.range || ""}`.trim(), "aria-label": `goal speed of ID ${id}` });
      const gcur = el("input", { type: "number", class: "ctl goal-current", min: gc.lo, max: gc.hi, placeholder: gc.unit || "raw",
        title: `goal-current ${gc.range || ""}${gc.unit ? " " + gc.unit : ""}`.trim(), "aria-label": `goal current of ID ${id}` });
      gspeed.addEventListener("change", () => Z.send("goals", at(bus, { id, speed: Number(gspeed.value) })));
      gcur.addEventListener("change", () => Z.send("goals", at(bus, { id, current: Number(gcur.value) })));
      const pos = el("span", { class: "num big", text: "–" });
      const bar = el("div", { class: "posbar" }, el("b"), el("i"));
      const moving = el("span", { class: "moving", title: "moving" });
      const cur = el("span", { class: "num", text: "–" }), volt = el("span", { class: "num", text: "–" });
      const vu = voltageOf(bus);
      const status = el("td");
      const btns = el("td", {}, el("div", { class: "row" },
        el("button", { class: "btn small ctl", onclick: () => { Z.choose(bus); readRegisters(id); } }, "Registers"),
        el("button", { class: "btn small ctl", onclick: () => { Z.choose(bus); check(id); } }, "Check"),
        el("button", { class: "btn small ctl", onclick: () => Z.send("stop", at(bus, { id })) }, "Stop")));
      const tr = el("tr", { id: Z.buses ? `act-${k}-${id}` : `act-${id}`, class: st.failed ? "failed" : null, "data-bus": Z.buses ? bus : null, "data-id": id },
        el("td", {}, sync), el("td", { class: "big num", text: id }),
        el("td", { class: "mono", text: a.model === null ? "–" : "0x" + a.model.toString(16).toUpperCase().padStart(4, "0") }),
        el("td", { class: "num", text: a.firmware ?? "–" }), el("td", { class: "num", text: a.baud }),
        el("td", { class: "num", text: a.return_mode ?? "–" }), status,
        el("td", { class: "pos" }, pos, moving, bar), el("td", { class: "goal" }, el("div", { class: "row" }, range, num),
          el("div", { class: "row goals" }, el("span", { class: "dim small", text: "speed" }), gspeed,
            el("span", { class: "dim small", text: "current" }), gcur)),
        el("td", {}, cur, el("span", { class: "dim", text: gc.unit ? ` ${gc.unit}` : " (raw)" })),
        el("td", { class: "volt" }, volt, el("span", { class: "dim", text: vu.unit ? ` ${vu.unit}` : " (raw)",
          title: vu.unit ? null : "the register map gives present-voltage no unit: the raw value" })), btns);
      rows[keyOf(bus, id)] = { a, st, tr, range, num, gspeed, gcur, pos, bar, moving, cur, volt, vu, span: [plo ?? 0, phi ?? 1], status,
                               touched: () => touched, seeded: false };
      status.append(statusTag(a, null, st));
      return tr;
  }
  function paintRows() {
    for (const key in rows) {
      const r = rows[key], s = live[key];
      if (r.st.failed && r.sig !== "failed") { r.sig = "failed"; r.status.replaceChildren(statusTag(r.a, s, r.st)); }
      if (!s || !s.fresh) continue;
      s.fresh = false;
      setText(r.pos, fmt(s.pos));
      setText(r.cur, fmt(s.cur));
      setText(r.volt, fmt(s.volt, r.vu.digits));
      r.moving.className = "moving" + (s.moving ? " on" : "");
      const [lo, hi] = r.span, at = (v) => (100 * Math.min(1, Math.max(0, (v - lo) / Math.max(1, hi - lo)))).toFixed(2);
      if (s.pos !== null) r.bar.lastChild.style.left = `calc(${at(s.pos)}% - 1px)`;
      if (s.goal !== null) r.bar.firstChild.style.left = `${at(s.goal)}%`;
      if (!r.seeded && s.goal !== null && !r.touched()) { r.range.value = s.goal; r.num.value = s.goal; r.seeded = true; }
      for (const [input, v] of [[r.gspeed, s.gspeed], [r.gcur, s.gcur]])   // what the actuator holds, unless being edited
        if (v !== null && v !== undefined && document.activeElement !== input && String(v) !== input.value) input.value = v;
      const sig = r.st.failed ? "failed" : `${r.a.baud}|${r.st.baud}|${r.a.polled}|${s.status}|${(s.errors || []).join()}`;
      if (r.sig !== sig) { r.sig = sig; r.status.replaceChildren(statusTag(r.a, s, r.st)); }
    }
  }

  // -- plots ---------------------------------------------------------------------------------
  // the polled actuators of every bus, as [bus, id]
  const polledAll = () => names().flatMap(bus => S(bus).failed ? []
    : S(bus).actuators.filter(a => a.polled && a.baud === S(bus).baud).map(a => [bus, a.id]));
  function buildPlots() {
    const polled = polledAll(), ids = polled.map(([bus, id]) => keyOf(bus, id));
    // one voltage plot a unit the maps give it (the raw values apart from volts)
    const unitOf = ([bus]) => voltageOf(bus).unit;
    const units = [...new Set(polled.map(unitOf))];
    const key = ids.join(",") + "|" + polled.map(unitOf).join(",");
    if (key === plotIds && plots) return;
    plotIds = key;
    const box = $("#plots");
    box.replaceChildren();
    const series = polled.map(([bus, id], i) => ({ label: Z.buses ? `${short(bus)} ID ${id}` : `ID ${id}`, color: COLORS[i % COLORS.length] }));
    const cu = [...new Set(polled.map(([bus]) => regOf(bus, "present-current").unit || null))];
    plots = { ids, pos: new Z.Plot(box, "Position", series, { window: 30 }),
              cur: new Z.Plot(box, cu.length === 1 && cu[0] ? `Current (${cu[0]})` : "Current", series, { window: 30 }),
              volt: units.map(u => {
                const keep = polled.map((p, i) => unitOf(p) === u ? i : -1).filter(i => i >= 0);
                const digits = keep.length ? voltageOf(polled[keep[0]][0]).digits : 0;
                return { keys: keep.map(i => ids[i]), plot: new Z.Plot(box, u ? `Voltage (${u})` : "Voltage (raw: the map gives no unit)",
                  keep.map(i => ({ ...series[i], digits })), { window: 30, digits }) };
              }) };
  }
  function plotSample(s) {
    if (!plots) return;
    const k = keyOf(s.bus, s.id), i = plots.ids.indexOf(k);
    if (i < 0 || s.status !== "ok") return;
    const t = s.w / 1000;
    const at = (v, n, j) => { const a = new Array(n).fill(null); a[j] = v; return a; };
    plots.pos.push(t, at(s.pos, plots.ids.length, i));
    plots.cur.push(t, at(s.cur, plots.ids.length, i));
    for (const g of plots.volt) { const j = g.keys.indexOf(k); if (j >= 0) g.plot.push(t, at(s.volt, g.keys.length, j)); }
  }
  Z.onFrame(() => paintRows());

  // -- registers -----------------------------------------------------------------------------
  async function readRegisters(id) {
    regId = id;
    $("#reg-id").textContent = Z.buses ? `of ID ${id} on bus ${Z.bus}` : `of ID ${id}`;
    $("#reg-refresh").dataset.off = "0";
    Z.renderControl();
    const r = await Z.send("registers", { id });
    if (!r) return;
    const tb = $("#registers tbody");
    tb.replaceChildren();
    for (const rec of r.records) {
      const info = regInfo[rec.register] || {};
      const mem = rec.memory === "NV" ? el("span", { class: "tag nv", text: "stored" })
        : rec.memory === "V" ? el("span", { class: "tag v", text: "volatile" }) : el("span", { class: "tag", text: "read-only" });
      let edit = el("span", { class: "dim", text: "" });
      if (rec.access === "RW") {
        const input = info.choices
          ? el("select", { class: "ctl", "aria-label": rec.register, "data-register": rec.register },
               Object.entries(info.choices).map(([k, v]) => el("option", { value: k, selected: Number(k) === rec.value }, `${k} ${v}`)))
          : el("input", { type: "number", class: "ctl", value: rec.value, min: info.lo, max: info.hi, "aria-label": rec.register,
                          "data-register": rec.register });
        // force: the library's rule for this register and value (info.force_values, from the same table)
        const forced = () => info.protected || (info.force_values || []).includes(Number(input.value));
        const btn = el("button", { class: "btn small ctl" + (forced() ? " danger" : ""), "data-register": rec.register,
          onclick: async () => {
            const d = await Z.send("write", { id, register: rec.register, value: Number(input.value) });
            if (d) { Z.toast(`${rec.register} = ${d.value} written` + (d.read_back !== undefined && d.read_back !== null ? ` (reads back ${d.read_back})` : ""), "info");
                     readRegisters(d.id); }
          } }, forced() ? "Write (force)" : "Write");
        input.addEventListener("change", () => { btn.textContent = forced() ? "Write (force)" : "Write";
                                                 btn.classList.toggle("danger", forced()); });
        edit = el("div", { class: "row" }, input, btn);
      }
      const phys = rec.physical !== undefined ? `${rec.physical} ${rec.unit}` : rec.meaning ? rec.meaning : rec.unit ? `${rec.value} ${rec.unit}` : "";
      tb.append(el("tr", {}, el("td", { class: "mono dim", text: protocol === "modbus" ? String(rec.address) : "0x" + rec.address.toString(16).toUpperCase().padStart(2, "0") }),
        el("td", { class: "name", text: rec.register, title: info.help || "" }), el("td", {}, mem),
        el("td", { class: "num", text: rec.value }), el("td", { class: "dim", text: phys }),
        el("td", { class: "dim small", text: info.choices ? `${Object.keys(info.choices).length} choices` : info.range || "" }),
        el("td", {}, edit)));
    }
    $("#registers").hidden = false;
    $("#reg-empty").hidden = true;
    Z.renderControl();
  }

  // -- check ---------------------------------------------------------------------------------
  async function check(id) {
    const r = await Z.send("check", { id, move: $("#check-move").checked });
    if (!r) return;
    const box = $("#check-out");
    box.className = "";
    box.replaceChildren(el("table", {}, el("thead", {}, el("tr", {}, ["check", "verdict", "value", "limit", "detail"].map(h => el("th", { text: h })))),
      el("tbody", {}, r.rows.map(row => el("tr", {}, el("td", { text: row.check }),
        el("td", { class: "verdict-" + row.verdict, text: row.verdict }), el("td", { class: "num", text: row.value ?? "–" }),
        el("td", { class: "dim", text: row.limit ?? "" }), el("td", { class: "dim", text: row.detail }))))));
    $("#check-note").firstChild.textContent = (Z.buses ? `bus ${Z.bus} ` : "") + `ID ${id}: ${r.rows[r.rows.length - 1].verdict} · `;
  }

  // -- fleet ---------------------------------------------------------------------------------
  function table(cols, items) {
    return el("table", {}, el("thead", {}, el("tr", {}, cols.map(([, h]) => el("th", { text: h })))),
      el("tbody", {}, items.map(it => el("tr", {}, cols.map(([k]) => el("td", { text: it[k] === null || it[k] === undefined ? "–" : Array.isArray(it[k]) ? it[k].join(", ") : it[k] }))))));
  }
  const readFile = () => Z.readFile($("#fleet-file"), "choose a fleet file first (.json, .toml, .yaml)");
  async function backup() {
    const r = await Z.send("backup", { format: $("#bk-format").value });
    if (!r) return;
    const url = URL.createObjectURL(new Blob([r.text], { type: "text/plain" }));
    const a = el("a", { href: url, download: r.filename });
    document.body.append(a); a.click(); a.remove();
    setTimeout(() => URL.revokeObjectURL(url), 10000);
    $("#fleet-out").replaceChildren(el("p", { class: "dim", text: `${r.filename} saved by the browser.` }));
  }
  async function diff() {
    const f = await readFile(); if (!f) return;
    const r = await Z.send("diff", { ...f, compare: $("#diff-compare").value });
    if (!r) return;
    $("#fleet-out").replaceChildren(r.rows.length ? table([["id", "ID"], ["register", "register"], ["memory", "memory"], ["a", "file"], ["b", "bus"], ["unit", "unit"]], r.rows)
      : el("p", { class: "okc", text: `The bus matches ${r.name}.` }));
  }
  async function apply(plan) {
    const f = await readFile(); if (!f) return;
    const r = await Z.send("apply", { ...f, plan });
    if (!r) return;
    const head = r.applied ? `${r.plan.length} writes made, ${r.failed} not verified; ${r.unchanged} settings already equal`
      : r.plan.length ? `${r.plan.length} writes planned; ${r.unchanged} settings already equal — nothing written yet` : `nothing to write: ${r.unchanged} settings already equal`;
    $("#fleet-out").replaceChildren(el("p", { class: r.failed ? "badc" : "", text: head }),
      r.plan.length ? table([["id", "ID"], ["register", "register"], ["memory", "memory"], ["old", "bus"], ["new", "file"], ["status", "status"], ["read_back", "read back"]], r.plan) : "");
  }

  // -- messages ------------------------------------------------------------------------------
  const pct = (arr, p) => { if (!arr.length) return null; const s = arr.slice(-400).sort((a, b) => a - b); return s[Math.min(s.length - 1, Math.floor(p * s.length))]; };
  let polls = 0, pollT = Date.now();
  const handlers = {
    hello(m) {
      $("#protocol").textContent = (m.protocol === "modbus" ? "Modbus RTU" : "IR protocol") + ` · ${m.model}`;
      $("#protocol").dataset.protocol = m.protocol;
      protocol = m.protocol;
      if (m.protocol === "modbus" && $("#scan-ids").value === "0-253") $("#scan-ids").value = "1-247";
      regInfo = Object.fromEntries(m.registers.map(r => [r.name, r]));
      // the chosen bus's ranges for what acts on it (sync move, cycle, the current limits)
      const [lo, hi] = rangeOf(Z.buses ? Z.bus : "", "goal-position", "present-position");
      if (lo !== null && hi !== null) for (const id of ["#sync-range", "#sync-pos", "#cycle-a", "#cycle-b"]) {
        const e = $(id); e.min = lo; e.max = hi;
        if (Number(e.value) > hi || Number(e.value) < lo) e.value = Math.round((lo + hi) / 2);
      }
      const gc = regOf(Z.buses ? Z.bus : "", "goal-current");
      for (const id of ["#play-limit", "#cycle-limit"]) { $(id).max = gc.hi ?? ""; $(id).placeholder = gc.unit || "raw"; }
      const box = $("#scan-bauds");
      box.replaceChildren(...m.bauds.map(b => el("label", { class: "inline" },
        el("input", { type: "checkbox", class: "ctl", value: b, checked: b === m.baud }), b)));
      Z.renderControl();
    },
    busy(m) {
      busy = m.job;
      $("#busy").classList.toggle("show", !!m.job);
      $("#busy-text").textContent = m.job ? (Z.buses ? `bus ${Z.bus}: ` : "") + `${m.job}…` : "";
      if (!m.job) $("#busy-bar").style.width = "0";
      $("#scan").disabled = !!m.job || !Z.controlling();
    },
    progress(m) {
      $("#busy-bar").style.width = `${(100 * m.done / Math.max(1, m.total)).toFixed(1)}%`;
      $("#busy-text").textContent = (Z.buses ? `bus ${Z.bus}: ` : "") + `${m.job}: ${m.text}`;
      if (m.job === "scan") $("#scan-note").textContent = `${m.done} of ${m.total} probes`;
    },
    controlchange(c) { $("#who").textContent = c.controller ? `controlling: ${c.controller.label}` : "nobody controls"; },
  };
  // every bus's table and live samples, whichever bus is chosen
  Z.every("actuators", (m) => { const st = S(m.bus); st.actuators = m.items; st.baud = m.baud; buildTable(); buildPlots(); renderBuses(); });
  Z.every("samples", (m) => {
    for (const s of m.items) { s.fresh = true; live[keyOf(s.bus, s.id)] = s; plotSample(s); Z.sawSample(s.w); polls++; }
  });
  Z.every("busy", (m) => { if (m.bus !== undefined) { S(m.bus).busy = m.job; renderBuses(); } });
  Z.every("failed", (m) => {
    if (m.bus === undefined) return;
    S(m.bus).failed = m.text;
    buildTable(); buildPlots(); renderBuses();
  });
  Z.every("hello", (m) => {
    if (m.buses) { for (const b of m.buses) S(b.name); renderBuses(); }
    else if (m.registers) { keepMap("", m.registers); buildTable(); buildPlots(); }
  });
  Z.every("bushello", (m) => { keepMap(m.bus, m.registers); buildTable(); buildPlots(); });
  Z.on("choose", () => {            // the panels of one bus start empty on another
    regId = null;
    $("#registers").hidden = true; $("#reg-empty").hidden = false; $("#reg-id").textContent = "";
    $("#reg-refresh").dataset.off = "1";
    $("#fleet-out").replaceChildren();
    $("#scan-note").textContent = "";
    renderBuses();
  });

  // -- the buses (several at once): each with its state; the chosen one is what the panels show
  function renderBuses() {
    if (!Z.buses) return;
    $("#buses-card").hidden = false;
    $("#scan-bus").textContent = `bus ${Z.bus}`;
    $("#buses").replaceChildren(...Z.buses.map((b, k) => {
      const st = S(b.name);
      const tag = st.failed ? el("span", { class: "tag bad state", text: "failed", title: st.failed })
        : st.busy ? el("span", { class: "tag warn state", text: st.busy })
        : el("span", { class: "tag ok state", text: `${st.actuators.length} actuator${st.actuators.length === 1 ? "" : "s"}` });
      return el("button", { class: "busbtn" + (b.name === Z.bus ? " chosen" : "") + (st.failed ? " failed" : ""), id: `bus-${k}`,
        "data-bus": b.name, title: `${b.port}: choose this bus for the panels below`, onclick: () => Z.choose(b.name) },
        el("b", { text: short(b.name) }), short(b.name) !== b.name ? el("span", { class: "small", text: b.name }) : "",
        b.port !== b.name ? el("span", { class: "dim small", text: b.port }) : "",
        el("span", { class: "tag", text: b.protocol === "modbus" ? "Modbus RTU" : "IR" }),
        b.simulated ? el("span", { class: "tag", text: "simulated", title: "nothing real can be harmed: no confirmation asked" }) : "", tag);
    }));
  }

  setInterval(() => {
    const dt = (Date.now() - pollT) / 1000, n = polledAll().length, baud = S(names()[0]).baud;
    const l = $("#link");
    const where = Z.buses ? `${names().length} buses` : `${baud} baud`;
    if (n) { l.textContent = `${where} · ${n} polled · ${fmt(polls / dt / n, 1)} polls/s each`; l.className = "pill ok"; }
    else { l.textContent = Z.buses || baud ? `${where} · no actuator polled` : "no actuators yet"; l.className = "pill warn"; }
    polls = 0; pollT = Date.now();
    const p50 = pct(Z.stats.latencies, .5), p99 = pct(Z.stats.latencies, .99);
    $("#lat").textContent = p50 === null ? "" : `latency p50 ${fmt(p50)} ms · p99 ${fmt(p99)} ms` + (Z.stats.dropped ? ` · ${Z.stats.dropped} dropped` : "");
  }, 1000);

  $("#scan").addEventListener("click", () => {
    const bauds = [...document.querySelectorAll("#scan-bauds input:checked")].map(i => Number(i.value));
    Z.send("scan", { ids: $("#scan-ids").value, bauds });
  });
  $("#cancel").addEventListener("click", () => Z.send("cancel"));
  $("#stopall").addEventListener("click", () => Z.send("stop", Z.buses ? { bus: null } : {}));
  $("#sync-range").addEventListener("input", () => { $("#sync-pos").value = $("#sync-range").value; });
  $("#sync-pos").addEventListener("change", () => { $("#sync-range").value = $("#sync-pos").value; });
  $("#sync").addEventListener("click", () => {
    const ticked = [...document.querySelectorAll("input.sync:checked")].map(i => [i.dataset.bus, Number(i.dataset.id)]);
    if (!ticked.length) { Z.toast("tick the actuators to move together first"); return; }
    const p = Number($("#sync-pos").value);
    // one Symmetric Store a bus
    for (const bus of [...new Set(ticked.map(([b]) => b))]) {
      const ids = ticked.filter(([b]) => b === bus).map(([, i]) => i);
      Z.send("sync", at(bus, { targets: Object.fromEntries(ids.map(i => [i, p])) }));
    }
    for (const [bus, i] of ticked) { const r = rows[keyOf(bus, i)]; if (r) { r.range.value = p; r.num.value = p; } }
  });
  $("#reg-refresh").addEventListener("click", () => { if (regId !== null) readRegisters(regId); });
  $("#backup").addEventListener("click", backup);
  $("#diff").addEventListener("click", diff);
  $("#plan").addEventListener("click", () => apply(true));
  $("#apply").addEventListener("click", () => apply(false));
  Z.connect(handlers);
})();
