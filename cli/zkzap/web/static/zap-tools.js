/* zkzap web, the mightyZAP console's further panels: a plot of any register, the packet panel
   and the bytes on the bus, play / teach / cycle. The console decides and does everything (the
   permissions a packet needs, the plan, the stop); this page only asks and shows. */
"use strict";
(() => {
  const { $, el, fmt } = Z;
  const COLORS = ["#4aa3ff", "#3fcf7a", "#f2b134", "#ff7b54", "#c59bff", "#57c7e6", "#ff5d9e", "#b5e853"];
  let registers = [], polled = [], busBaud = null;
  const stamp = () => new Date().toISOString().slice(0, 19).replace(/[:T]/g, "").replace(/^(\d{8})/, "$1-");

  // -- the register plot ---------------------------------------------------------------------
  let rplot = null, rplotKey = "", rplotReg = null, rplotSeries = [];
  function regInfo(name) { return registers.find(r => r.name === name); }
  function buildRegPlot() {
    const key = `${Z.bus}|${rplotReg}|${polled.join(",")}`;
    if (key === rplotKey) return;
    rplotKey = key;
    const box = $("#rplot");
    box.replaceChildren();
    rplot = null;
    $("#rplot-pause").textContent = "Pause";
    if (!rplotReg) { $("#rplot-note").textContent = "choose a register"; return; }
    const info = regInfo(rplotReg) || {};
    const digits = info.scale && info.scale < 1 ? 1 : 0;
    rplotSeries = polled.map((id, i) => ({ label: `ID ${id}`, color: COLORS[i % COLORS.length], digits }));
    const title = rplotReg + (info.unit ? ` (${info.unit})` : "");
    rplot = new Z.Plot(box, title, rplotSeries, { window: Number($("#rplot-window").value), zoom: true, height: 220, digits, max: 20000 });
    rplot.ids = polled.slice();
    rplot.onpause = (on) => { $("#rplot-pause").textContent = on ? "Live" : "Pause"; };
    rplot.title = title;
    $("#rplot-note").textContent = `${rplotReg}, polled with the live view · ${info.memory === "NV" ? "stored" : info.memory === "V" ? "volatile" : "read-only"}`;
  }
  Z.on("samples", (m) => {
    if (!rplot) return;
    const n = rplot.ids.length;
    for (const s of m.items) {
      if (s.reg === undefined || s.reg === null || s.status !== "ok" || !Z.mine(s)) continue;
      const i = rplot.ids.indexOf(s.id);
      if (i < 0) continue;
      const a = new Array(n).fill(null); a[i] = s.reg;
      rplot.push(s.w / 1000, a);
    }
  });
  $("#rplot-reg").addEventListener("change", () => Z.send("plot", { register: $("#rplot-reg").value }));
  $("#rplot-window").addEventListener("change", () => { if (rplot) { rplot.window = Number($("#rplot-window").value); rplot.pause(false); } });
  $("#rplot-pause").addEventListener("click", () => { if (rplot) rplot.pause(!rplot.paused); });
  $("#rplot-csv").addEventListener("click", () => {
    if (!rplot) { Z.toast("choose a register to plot first"); return; }
    Z.download(`${rplotReg}-${stamp()}.csv`, rplot.csv(rplot.ids.map(i => `id${i}`)), "text/csv");
  });
  $("#rplot-png").addEventListener("click", () => {
    if (!rplot) { Z.toast("choose a register to plot first"); return; }
    Z.download(`${rplotReg}-${stamp()}.png`, rplot.png(rplot.title, rplotSeries));
  });

  // -- the packet panel ----------------------------------------------------------------------
  // what each instruction (an IR instruction, or a Modbus function) takes beside a register:
  // "length" (Load Data), "count" (Read Holding Registers), "value", "values" (Write Multiple), or none
  let takes = {};
  const LABELS = { length: "Length ", count: "Count ", value: "Value ", values: "Values " };
  function packetFields() {
    const ins = $("#pkt-ins").value, reg = $("#pkt-reg").value, kind = takes[ins];
    const f = { instruction: ins, id: Number($("#pkt-id").value) };
    const v = $("#pkt-value").value.trim();
    if (reg && kind) {
      f.register = reg;
      if (kind === "values") f.values = v;
      else if (kind === "value") f.value = v === "" ? null : Number(v);
      else if (v !== "") f[kind] = Number(v);
    } else f.params = $("#pkt-params").value;
    return f;
  }
  function packetForm() {
    const ins = $("#pkt-ins").value, kind = takes[ins], reg = kind && $("#pkt-reg").value;
    $("#pkt-reg").disabled = !kind || !Z.controlling();
    $("#pkt-value-l").style.display = reg ? "" : "none";
    $("#pkt-value-l").firstChild.textContent = LABELS[kind] || "Value ";
    $("#pkt-value").placeholder = kind === "values" ? "like 1000 800" : "";
    $("#pkt-params-l").style.display = reg ? "none" : "";
  }
  let composeN = 0;
  async function composePacket() {
    packetForm();
    const n = ++composeN;
    let r;
    try { r = await Z.request("compose", packetFields()); }
    catch (e) { if (n === composeN) { $("#pkt-frame").textContent = "–"; $("#pkt-describe").textContent = e.message; $("#pkt-needs").replaceChildren(); } return; }
    if (n !== composeN) return;
    $("#pkt-frame").textContent = r.frame;
    $("#pkt-describe").textContent = r.describe + (r.reply ? " · a reply is expected" : " · no reply expected");
    $("#pkt-needs").replaceChildren(...(r.needs.length ? r.needs.map(x => el("li", {}, el("b", { text: x.permission }), `: ${x.reason}`))
      : [el("li", { class: "none", text: "needs no permission" })]));
    $("#pkt-asks").textContent = r.asks === "force" ? "asks for force and consent" : r.asks === "stored-write" ? "asks for consent" : r.needs.length ? "waived on this port" : "";
  }
  const composeSoon = Z.throttle(composePacket, 150);
  for (const id of ["#pkt-ins", "#pkt-reg", "#pkt-id", "#pkt-value", "#pkt-params"]) {
    $(id).addEventListener("input", composeSoon);
    $(id).addEventListener("change", composeSoon);
  }
  $("#pkt-send").addEventListener("click", async () => {
    $("#pkt-reply").textContent = "sending…";
    const r = await Z.send("packet", packetFields());
    if (!r) { $("#pkt-reply").textContent = "not sent"; return; }
    $("#pkt-reply").textContent = r.reply ? `reply ${r.reply} in ${fmt(r.rtt_ms, 1)} ms` + (r.exception ? ` · ${r.exception}`
      : r.errors && r.errors.length ? ` · errors: ${r.errors.join(", ")}` : "") : r.note;
  });

  // -- the bytes on the bus ------------------------------------------------------------------
  let trafficPaused = false;
  const TRAFFIC_KEPT = 400;
  // items are drawn once per animation frame, only the newest TRAFFIC_KEPT of those that came
  // meanwhile: a bus busy with a play or cycle (hundreds of packets a second) costs the page one
  // bounded redraw a frame, never a backlog that keeps it from answering a click
  const clock = new Intl.DateTimeFormat("en-GB", { hour12: false, hour: "2-digit", minute: "2-digit", second: "2-digit" });
  let trafficPending = [], trafficDrawn = false;
  function drawTraffic() {
    trafficDrawn = false;
    const items = trafficPending.slice(-TRAFFIC_KEPT);
    trafficPending = [];
    const box = $("#traffic");
    const frag = document.createDocumentFragment();
    for (let k = items.length - 1; k >= 0; k--) {
      const it = items[k];
      frag.append(el("div", { class: (it.dir === "tx" ? "tx" : "rx") + (it.bad ? " bad" : "") + (it.poll ? " poll" : ""), title: it.hex },
        el("span", { class: "t num dim", text: clock.format(new Date(it.w)) + "." + String(Math.floor(it.w % 1000)).padStart(3, "0") }),
        el("b", { text: it.dir === "tx" ? " → " : " ← " }), el("span", { text: it.text }), el("span", { class: "h", text: it.hex + (it.n > 64 ? ` … (${it.n} bytes)` : "") })));
    }
    const atTop = box.scrollTop < 4;
    box.prepend(frag);
    while (box.childElementCount > TRAFFIC_KEPT) box.lastChild.remove();
    if (atTop) box.scrollTop = 0;
  }
  Z.on("traffic", (m) => {
    if (trafficPaused) return;
    for (const it of m.items) trafficPending.push(it);
    if (trafficPending.length > 4 * TRAFFIC_KEPT) trafficPending = trafficPending.slice(-TRAFFIC_KEPT);
    if (!trafficDrawn) { trafficDrawn = true; requestAnimationFrame(drawTraffic); }
  });
  $("#traffic-polls").addEventListener("change", () => Z.send("traffic", { polls: $("#traffic-polls").checked }));
  $("#traffic-pause").addEventListener("click", () => { trafficPaused = !trafficPaused; $("#traffic-pause").textContent = trafficPaused ? "Go on" : "Pause"; });
  $("#traffic-clear").addEventListener("click", () => { trafficPending = []; $("#traffic").replaceChildren(); });
  Z.on("traffic-polls", (m) => { $("#traffic-polls").checked = m.polls; });

  // -- play ----------------------------------------------------------------------------------
  const readPath = () => Z.readFile($("#play-file"), "choose a path file first (.csv, .json, .jsonl: rows of t, id, position)");
  function playOptions() {
    return { interpolate: $("#play-interp").checked ? "linear" : null, rate: $("#play-interp").checked ? Number($("#play-rate").value) : null,
             loops: Number($("#play-loops").value || 1), limit: $("#play-limit").value === "" ? null : Number($("#play-limit").value),
             stop: $("#play-stop").value };
  }
  async function plan() {
    const f = await readPath(); if (!f) return;
    const r = await Z.send("plan", { ...f, ...playOptions() });
    if (!r) return;
    $("#play-note").textContent = `${r.total} steps, ${fmt(r.duration, 2)} s`;
    $("#play-out").replaceChildren(el("p", { class: "dim", text: `${r.name}: ${r.note}; ${r.total} steps, ${r.frames} frames, IDs ${r.ids.join(", ")}` }),
      el("table", {}, el("tbody", {}, r.steps.slice(0, 60).map(s => el("tr", {}, el("td", { class: "num", text: s.t.toFixed(3) }),
        el("td", { class: "mono", text: s.frames.join(" · ") }))))));
  }
  async function play(taught) {
    const f = taught ? { taught: true } : await readPath(); if (!f) return;
    $("#play-out").replaceChildren(el("p", { class: "dim", text: "playing…" }));
    await Z.send("play", { ...f, ...playOptions() });
  }
  Z.on("played", (r) => {
    const s = r.summary;
    const rows = [["steps", s.steps], ["lateness p50", `${fmt(s.lateness_p50_ms, 2)} ms`], ["lateness p99", `${fmt(s.lateness_p99_ms, 2)} ms`],
      ["lateness max", `${fmt(s.lateness_max_ms, 2)} ms`], ["log reads", `${s.reads} (${s.read_failures} unanswered)`],
      ...Object.entries(r.worst).map(([id, v]) => [`ID ${id} worst tracking error`, `${v} counts`])];
    $("#play-note").textContent = r.stopped ? `stopped: ${r.stopped.reason}` : `${r.name}: played`;
    $("#play-out").replaceChildren(
      r.stopped ? el("p", { class: "badc", text: `${r.stopped.message}; held: ${Object.entries(r.stopped.positions).map(([i, p]) => `ID ${i} at ${p}`).join(", ") || "–"}` }) : "",
      r.unsettled && r.unsettled.length ? el("p", { class: "warnc", text: `IDs ${r.unsettled.join(", ")} away from their last goal` }) : "",
      el("table", { id: "play-summary" }, el("tbody", {}, rows.map(([k, v]) => el("tr", {}, el("td", { class: "dim", text: k }), el("td", { class: "num", text: v }))))));
  });
  $("#play-plan").addEventListener("click", plan);
  $("#play-go").addEventListener("click", () => play(false));

  // -- teach ---------------------------------------------------------------------------------
  let taught = [];
  function teachTable() {
    const byT = new Map();
    for (const r of taught) { if (!byT.has(r.t)) byT.set(r.t, {}); byT.get(r.t)[r.id] = r.position; }
    const ids = [...new Set(taught.map(r => r.id))].sort((a, b) => a - b);
    const last = [...byT.entries()].slice(-30);
    $("#teach-out").replaceChildren(taught.length ? el("table", {}, el("thead", {}, el("tr", {}, el("th", { text: "t" }), ids.map(i => el("th", { text: `ID ${i}` })))),
      el("tbody", {}, last.map(([t, p]) => el("tr", {}, el("td", { class: "num", text: fmt(t, 2) }), ids.map(i => el("td", { class: "num", text: p[i] ?? "–" })))))) : "");
  }
  Z.on("teach", (m) => {
    if (m.append) taught.push(...m.rows); else taught = m.rows.slice();
    const points = new Set(taught.map(r => r.t)).size;
    $("#teach-note").textContent = m.ids.length ? `IDs ${m.ids.join(", ")} · ${points} waypoints` + (m.rate ? ` · ${m.rate}/s` : "") : "not teaching";
    teachTable();
  });
  $("#teach-start").addEventListener("click", () => Z.send("teach", { ids: $("#teach-ids").value, rate: $("#teach-rate").value === "" ? null : Number($("#teach-rate").value) }));
  $("#teach-take").addEventListener("click", () => Z.send("teach-take"));
  $("#teach-stop").addEventListener("click", () => Z.send("teach-stop"));
  $("#teach-save").addEventListener("click", async () => { const r = await Z.send("teach-file", { format: "csv" }); if (r) Z.download(r.filename, r.text, "text/csv"); });
  $("#teach-play").addEventListener("click", () => play(true));

  // -- cycle ---------------------------------------------------------------------------------
  let cplot = null;
  function cyclePlot() {
    const box = $("#cycle-plot");
    box.replaceChildren();
    cplot = new Z.Plot(box, "By cycle: reach time (ms), peak current (mA, right)", [
      { label: "reach B", color: COLORS[0] }, { label: "reach A", color: COLORS[1] }, { label: "peak mA", color: COLORS[3], scale: "r" }],
      { rolling: false, right: true, height: 200, res: 0 });
  }
  // the chosen bus's voltage as its map gives it (volts, or the raw value where the map gives no unit)
  const volts = () => Z.voltageOf(Z.buses ? Z.bus : "");
  function cycleRow(c) {
    const vu = volts(), v = vu.unit ? c.min_voltage_v : c.min_voltage_raw ?? c.min_voltage_v;
    return el("tr", { class: c.status === "ok" ? "" : "badc" }, [c.cycle, fmt(c.reach_b_s * 1000), fmt(c.reach_a_s === null ? null : c.reach_a_s * 1000),
      c.overshoot_b, c.overshoot_a ?? "–", c.peak_current_ma, fmt(c.mean_current_ma, 1), v === null || v === undefined ? "–" : vu.unit ? fmt(v, vu.digits) : `${fmt(v)} (raw)`,
      c.polls, c.status]
      .map(v => el("td", { class: "num", text: v ?? "–" })));
  }
  function cycleTable() {
    let t = $("#cycle-table");
    if (!t) {
      const vu = volts();
      t = el("table", { id: "cycle-table" }, el("thead", {}, el("tr", {}, ["cycle", "reach B ms", "reach A ms", "over B", "over A", "peak mA", "mean mA",
        vu.unit ? `min ${vu.unit}` : "min voltage (raw)", "polls", "status"]
        .map(h => el("th", { text: h })))), el("tbody"));
      $("#cycle-out").replaceChildren(t);
    }
    return t.tBodies[0];
  }
  Z.on("cycles", (m) => {
    if (m.reset || !cplot) { cyclePlot(); $("#cycle-out").replaceChildren(); $("#cycle-sum").textContent = m.id !== undefined ? `ID ${m.id}: ${m.between.join(" ↔ ")}` : ""; }
    const tb = cycleTable();
    for (const c of m.items) {
      tb.prepend(cycleRow(c));
      cplot.push(c.cycle, [c.reach_b_s === null ? null : c.reach_b_s * 1000, c.reach_a_s === null ? null : c.reach_a_s * 1000, c.peak_current_ma]);
    }
    while (tb.childElementCount > 200) tb.lastChild.remove();
  });
  Z.on("cycled", (s) => {
    $("#cycle-note").textContent = s.reason === "done" ? "done" : `stopped: ${s.reason}`;
    $("#cycle-sum").textContent = `${s.cycles} cycles in ${fmt(s.seconds, 1)} s · ${fmt(s.polls_per_s, 1)} polls/s (${fmt(s.ratio, 2)}x the wire limit of ${fmt(s.wire_limit, 1)}/s)`
      + (s.reason !== "done" ? ` · ${s.why}` : "");
  });
  $("#cycle-go").addEventListener("click", () => {
    const v = (id) => $(id).value === "" ? null : Number($(id).value);
    $("#cycle-note").textContent = "running";
    Z.send("cycle", { id: v("#cycle-id"), a: v("#cycle-a"), b: v("#cycle-b"), cycles: v("#cycle-n"), dwell: v("#cycle-dwell"), limit: v("#cycle-limit") });
  });

  // -- what the console says -----------------------------------------------------------------
  Z.on("hello", (m) => {
    registers = m.registers || [];
    busBaud = m.baud;
    const sel = $("#rplot-reg");
    const addr = (r) => m.protocol === "modbus" ? String(r.address) : `0x${r.address.toString(16).toUpperCase().padStart(2, "0")}`;   // as the register table
    sel.replaceChildren(el("option", { value: "", text: "none" }), ...registers.map(r => el("option", { value: r.name, text: `${r.name} (${addr(r)})` })));
    sel.value = m.plotted || "";
    rplotReg = m.plotted || null;
    const pr = $("#pkt-reg");
    pr.replaceChildren(el("option", { value: "", text: "raw parameters" }), ...registers.map(r => el("option", { value: r.name, text: r.name })));
    pr.value = "goal-position";
    takes = Object.fromEntries((m.instructions || []).map(i => [i.name, i.takes]));
    $("#pkt-ins").replaceChildren(...(m.instructions || []).map(i => el("option", { value: i.name, title: i.help,
      text: `${i.name} (0x${i.code.toString(16).toUpperCase().padStart(2, "0")})` + (i.documented ? "" : " · undocumented") })));
    $("#pkt-ins").value = m.protocol === "modbus" ? "read" : "load";
    if (m.packet_ids) { $("#pkt-id").max = m.packet_ids.hi; $("#pkt-id").title = `0..${m.packet_ids.hi}; ${m.packet_ids.broadcast}: every actuator (broadcast)`; }
    $("#pkt-params").placeholder = m.protocol === "modbus" ? "data bytes, like 00 D2 00 01" : "hex, like 8C 02";
    $("#traffic-polls").checked = !!m.traffic_polls;
    buildRegPlot();
    setTimeout(composePacket, 0);
  });
  Z.on("plot", (m) => { rplotReg = m.register; $("#rplot-reg").value = m.register || ""; buildRegPlot(); });
  Z.on("actuators", (m) => {
    busBaud = m.baud;
    polled = m.items.filter(a => a.polled && a.baud === busBaud).map(a => a.id);
    buildRegPlot();
    if (polled.length && !polled.includes(Number($("#cycle-id").value))) $("#cycle-id").value = polled[0];
    if (polled.length && !polled.includes(Number($("#pkt-id").value))) { $("#pkt-id").value = polled[0]; composeSoon(); }
  });
  Z.on("controlchange", () => packetForm());
  Z.on("choose", () => {            // another bus: its own bytes, plan, play and cycles from now on
    $("#traffic").replaceChildren();
    for (const id of ["#play-out", "#cycle-out", "#cycle-plot"]) $(id).replaceChildren();
    for (const id of ["#play-note", "#cycle-note", "#cycle-sum", "#pkt-reply"]) $(id).textContent = "";
    cplot = null;
  });
})();
