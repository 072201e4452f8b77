/* zkzap web: what both consoles share — the WebSocket, requests and consent, who controls,
   the activity log, toasts, plots (uPlot) and the figures a benchmark reads (window.zkzapStats). */
"use strict";

const Z = (() => {
  const $ = (sel, root = document) => root.querySelector(sel);
  const el = (tag, attrs = {}, ...kids) => {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (v === null || v === undefined || v === false) continue;
      if (k === "class") e.className = v;
      else if (k === "text") e.textContent = v;
      else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
      else e.setAttribute(k, v === true ? "" : v);
    }
    for (const kid of kids.flat()) if (kid !== null && kid !== undefined) e.append(kid instanceof Node ? kid : String(kid));
    return e;
  };
  const fmt = (v, digits = 0) => (v === null || v === undefined || Number.isNaN(v)) ? "–"
    : Number(v).toLocaleString("en-US", { minimumFractionDigits: digits, maximumFractionDigits: digits });
  const setText = (e, text) => { if (e.textContent !== text) e.textContent = text; };
  const setClass = (e, cls) => { if (e.className !== cls) e.className = cls; };
  const clock = (t) => new Date(t * 1000).toLocaleTimeString("en-GB", { hour12: false });

  // -- figures for benchmarks and tests ------------------------------------------------------
  const stats = { produced: 0, samples: 0, batches: 0, latencies: [], renderLatencies: [], serverLatencies: [], pageLatencies: [], dropped: 0, errors: 0, failures: 0, connected: false };
  window.zkzapStats = stats;
  stats.longest = 0;               // the longest main-thread task seen (ms)
  try {
    new PerformanceObserver((list) => { for (const e of list.getEntries()) stats.longest = Math.max(stats.longest, e.duration); })
      .observe({ type: "longtask", buffered: true });
  } catch (e) { /* not every browser has long-task timing */ }
  const keep = (arr, v) => { arr.push(v); if (arr.length > 20000) arr.splice(0, arr.length - 20000); };

  // -- the socket ----------------------------------------------------------------------------
  let ws = null, handlers = {}, me = null, controller = null, hello = null, reqN = 0, backoff = 500;
  const pending = new Map();

  function connect(h) {
    handlers = h;
    open();
  }
  function open() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    ws = new WebSocket(`${proto}//${location.host}/ws`);
    ws.onopen = () => { backoff = 500; stats.connected = true; setConn("connected", "ok");
      ws.send(JSON.stringify({ op: "hello", name: localStorage.getItem("zkzap-name") || "" })); };
    ws.onclose = (ev) => {
      stats.connected = false;
      for (const [, p] of pending) p.reject(new Error("disconnected"));
      pending.clear();
      setConn(ev.code === 1001 ? "console ended" : "disconnected — retrying", "bad");
      controller = null; me = null; renderControl();
      setTimeout(open, backoff); backoff = Math.min(backoff * 2, 5000);
    };
    ws.onmessage = (ev) => {
      const msg = JSON.parse(ev.data);
      if (msg.type === "samples") {
        const now = Date.now();
        stats.batches++;
        for (const it of msg.items) { stats.samples++; if (it.w) keep(stats.latencies, now - it.w); }
        if (msg.items.length && msg.items[0].w) { keep(stats.serverLatencies, msg.s - msg.items[0].w); keep(stats.pageLatencies, now - msg.s); }
      }
      dispatch(msg);
    };
  }
  function dispatch(msg) {
    switch (msg.type) {
      case "ping":
        if (stats.lastPing) stats.pingGap = Math.max(stats.pingGap || 0, Date.now() - stats.lastPing);
        stats.lastPing = Date.now();
        stats.dropped = msg.dropped || 0;
        stats.produced = msg.produced || 0;
        stats.producedAt = msg.t;         // the console's clock when it counted them
        ws.send(JSON.stringify({ op: "pong", n: msg.n, t: msg.t }));
        return;
      case "hello": me = msg.you; hello = msg; $("#port").textContent = msg.port + (msg.simulated ? " (simulated)" : "");
        $("#port").title = msg.buses ? msg.buses.map(b => b.port).join(", ") : msg.port;
        buses = msg.buses || null;
        if (buses && !buses.some(b => b.name === chosen)) chosen = buses.length ? buses[0].name : null;
        break;
      case "control": controller = msg.controller; renderControl(msg); break;
      case "log": addLog(msg); break;
      case "logs": $("#log").replaceChildren(); msg.items.forEach(addLog); break;
      case "done": { const p = pending.get(msg.req); if (p) { pending.delete(msg.req); p.resolve(msg); } break; }
      case "error": {
        const p = pending.get(msg.req);
        if (p) { pending.delete(msg.req); p.reject(new Error(msg.text)); }
        else toast(msg.text);
        break;
      }
      case "consent": {
        const p = pending.get(msg.req);
        if (p) { pending.delete(msg.req); askConsent(msg, p); }
        break;
      }
      case "failed": banner(msg.bus !== undefined ? `Bus ${msg.bus} stopped: ${msg.text}` : `The console stopped: ${msg.text}`, "error"); break;
    }
    for (const f of everyListeners[msg.type] || []) f(msg);
    if (buses) {
      // several buses: what a bus says is kept (shown when that bus is chosen); the page's panels
      // hear the chosen bus, and what names no bus (the log, who controls, the live batches)
      if (msg.bus !== undefined) {
        const kept = busState[msg.bus] = busState[msg.bus] || {};
        if (KEPT.includes(msg.type)) kept[msg.type] = msg;
        else if (msg.type === "cycles") {      // a run's records: since its reset, the last few hundred
          kept.cycles = msg.reset ? [msg] : [...(kept.cycles || []), msg].slice(-400);
          if (msg.reset) delete kept.cycled;
        }
        if (msg.bus !== chosen) return;
        if (msg.type === "bushello") { deliver({ ...msg, type: "hello" }); return; }
      } else if (msg.type === "hello") return;     // each bus's own hello comes as bushello
    }
    deliver(msg);
  }
  function deliver(msg) {
    const fn = handlers[msg.type];
    if (fn) fn(msg);
    for (const f of listeners[msg.type] || []) f(msg);
  }
  // more handlers of a message type, beside the page's own (a page's further panels)
  const listeners = {};
  function on(type, f) { (listeners[type] = listeners[type] || []).push(f); }
  // handlers of every message of a type, whichever bus it names (the actuators of every bus)
  const everyListeners = {};
  function every(type, f) { (everyListeners[type] = everyListeners[type] || []).push(f); }

  // -- several buses: one is chosen, the one the panels show and the requests go to ---------
  let buses = null, chosen = null;
  const busState = {};
  // what a bus's console says of its state, shown again when that bus is chosen (in this order)
  const KEPT = ["bushello", "actuators", "busy", "plot", "traffic-polls", "teach", "played", "cycled"];
  function choose(name) {
    if (!buses || name === chosen || !buses.some(b => b.name === name)) return;
    chosen = name;
    for (const f of listeners.choose || []) f({ bus: name });
    const kept = busState[name] || {};
    for (const type of KEPT) {
      if (type === "cycled") for (const m of kept.cycles || []) deliver(m);    // a cycle run's records, then its end
      if (kept[type]) deliver(type === "bushello" ? { ...kept[type], type: "hello" } : kept[type]);
    }
    renderControl();
  }
  // whether a live item (a sample, a byte on the bus) is the chosen bus's
  const mine = (item) => !buses || item.bus === chosen;

  // a request: resolves with the reply; a consent reply asks the person and sends it again
  function request(op, fields = {}, grant = []) {
    return new Promise((resolve, reject) => {
      if (!ws || ws.readyState !== WebSocket.OPEN) { reject(new Error("not connected")); return; }
      const req = ++reqN;
      const msg = { op, req, ...(buses && !("bus" in fields) ? { bus: chosen } : {}), ...fields, grant };
      pending.set(req, { resolve, reject, msg });
      ws.send(JSON.stringify(msg));
    });
  }
  // the same, with errors shown as toasts (null on failure)
  async function send(op, fields = {}) {
    try { return await request(op, fields); }
    catch (e) { if (e.message !== "cancelled") toast(e.message); return null; }
  }

  // -- consent -------------------------------------------------------------------------------
  const TITLES = { "stored-write": "Write stored settings?", force: "Force this write?",
                   engine: "Start the engine?", move: "Move through the full stroke?" };
  const OK = { "stored-write": "Write", force: "Write anyway", engine: "Start", move: "Move" };
  function askConsent(msg, p) {
    const m = $("#modal");
    $("#modal-title").textContent = TITLES[msg.permission] || "Confirm";
    $("#modal-text").textContent = msg.text;
    const force = $("#modal-force");
    force.parentElement.style.display = msg.permission === "force" ? "" : "none";
    force.checked = false;
    const ok = $("#modal-ok");
    ok.textContent = OK[msg.permission] || "Confirm";
    ok.className = "btn " + (msg.permission === "engine" ? "go" : "danger");
    ok.disabled = msg.permission === "force";
    force.onchange = () => { ok.disabled = !force.checked; };
    m.classList.add("show");
    m.dataset.permission = msg.permission;
    const close = () => { m.classList.remove("show"); ok.onclick = null; $("#modal-cancel").onclick = null; };
    ok.onclick = () => {
      close();
      const grant = [...(p.msg.grant || []), msg.permission];
      request(p.msg.op, Object.fromEntries(Object.entries(p.msg).filter(([k]) => !["op", "req", "grant"].includes(k))), grant)
        .then(p.resolve, p.reject);
    };
    $("#modal-cancel").onclick = () => { close(); p.reject(new Error("cancelled")); addLog({ t: Date.now() / 1000, level: "info", text: "not done: confirmation refused" }); };
    setTimeout(() => ok.disabled ? $("#modal-cancel").focus() : ok.focus(), 0);
  }

  // -- who controls --------------------------------------------------------------------------
  function controlling() { return me !== null && controller && controller.id === me; }
  function renderControl() {
    const box = $("#control");
    box.replaceChildren();
    box.className = "control";
    if (me === null) { box.append(el("span", { class: "dim", text: "not connected" })); }
    else if (controlling()) {
      box.classList.add("me");
      box.append(el("span", {}, "You control ", el("span", { class: "dim", text: `(${controller.name})` })),
        el("button", { class: "btn small", id: "release", onclick: () => release() }, "Release"));
    } else if (controller) {
      box.classList.add("other");
      box.append(el("span", {}, "View only — ", el("b", { text: controller.label }), " controls"));
    } else {
      box.append(el("span", { text: "Nobody controls" }),
        el("button", { class: "btn small primary", id: "take", onclick: () => send("take") }, "Take control"));
    }
    document.body.classList.toggle("viewonly", !controlling());
    document.querySelectorAll(".ctl").forEach(e => { if ("disabled" in e) e.disabled = !controlling() || e.dataset.off === "1"; });
    if (handlers.controlchange) handlers.controlchange({ controlling: controlling(), controller });
    for (const f of listeners.controlchange || []) f({ controlling: controlling(), controller });
  }
  function release() {
    const warn = hello && hello.kind === "zk" ? "Releasing control sends the engine to standby if this page runs it. " : "";
    if (warn && !confirm(warn + "Release control?")) return;
    send("release");
  }

  // -- status, log, toasts, banners ----------------------------------------------------------
  function setConn(text, cls) { const c = $("#conn"); c.textContent = text; c.className = "pill " + cls; }
  function addLog(e) {
    const box = $("#log");
    if (!box) return;
    box.prepend(el("div", { class: e.level }, el("span", { class: "t num", text: clock(e.t) }),
      e.bus !== undefined ? el("span", { class: "busname", text: e.bus }) : null, e.text));
    while (box.childElementCount > 300) box.lastChild.remove();
  }
  function toast(text, kind = "") {
    if (!kind) addLog({ t: Date.now() / 1000, level: "error", text });   // errors stay in the log
    stats.failures += kind ? 0 : 1;
    const t = el("div", { class: "toast " + kind, role: "alert", text });
    $("#toasts").append(t);
    setTimeout(() => t.remove(), 6000);
  }
  function banner(text, kind = "info", id = "#banner") {
    const b = $(id);
    if (!b) return;
    b.className = `banner ${kind}` + (text ? " show" : "");
    b.textContent = text || "";
  }

  // -- plots ---------------------------------------------------------------------------------
  const PLOT_FPS = 5;
  const allPlots = [];
  let nextPlot = 0;
  // at most one plot repaints per animation frame, in turn: the work is spread over the frames
  function drawOnePlot(now) {
    for (let k = 0; k < allPlots.length; k++) {
      const p = allPlots[(nextPlot + k) % allPlots.length];
      if (p.u.root.isConnected && p.due(now)) { p.draw(now); nextPlot = (nextPlot + k + 1) % allPlots.length; return; }
    }
  }
  // one uPlot over a rolling time window; push() adds a point, draw() (once per frame) repaints
  class Plot {
    constructor(box, title, series, opts = {}) {
      this.window = opts.window || 60;
      this.res = opts.res ?? 0.04;
      this.max = opts.max || 12000;
      this.n = series.length;
      this.data = [[], ...series.map(() => [])];
      const key = el("span", { class: "keys" }, series.map(s => el("span", { class: "key" }, el("i", { style: `background:${s.color}` }), s.label)));
      const wrap = el("div", { class: "plot" }, el("div", { class: "title" }, el("b", { text: title }), key));
      const area = el("div");
      wrap.append(area);
      box.append(wrap);
      const axis = { stroke: "#8b9bab", grid: { stroke: "#2c3a48", width: 1 }, ticks: { stroke: "#2c3a48" } };
      this.rolling = opts.rolling !== false;   // a rolling time window, or x any number (a cycle's) shown whole
      const scales = { x: { time: this.rolling } };
      const hhmmss = (u, v) => v.map(x => new Date(x * 1000).toLocaleTimeString("en-GB", { hour12: false }));
      const short = (x) => Math.abs(x) >= 10000 ? `${fmt(x / 1000)}k` : fmt(x, opts.digits ?? 0);
      const counted = { values: (u, v) => v.map(short), incrs: [1, 2, 5, 10, 20, 50, 100, 200, 500, 1e3, 2e3, 5e3, 1e4, 1e5, 1e6, 1e7] };
      const axes = [{ ...axis, ...(this.rolling ? { values: hhmmss } : counted), space: 70 }, { ...axis, size: 56, values: (u, v) => v.map(short) }];
      if (opts.right) {
        scales.r = { range: opts.rightRange || undefined };
        axes.push({ ...axis, scale: "r", side: 1, grid: { show: false }, size: 50 });
      }
      if (opts.range) scales.y = { range: opts.range };
      this.u = new uPlot({
        width: Math.max(area.clientWidth || wrap.clientWidth || 300, 200), height: opts.height || 170,
        scales, axes, legend: { show: false },
        cursor: { drag: { x: !!opts.zoom, y: false, setScale: false } },
        hooks: opts.zoom ? { setSelect: [(u) => this.zoomTo(u)] } : {},
        series: [{}, ...series.map(s => ({ label: s.label, stroke: s.color, width: s.width || 1.6, dash: s.dash, scale: s.scale || "y", spanGaps: true,
                                            points: { show: false }, value: (u, v) => fmt(v, s.digits ?? opts.digits ?? 0) }))],
      }, this.data, area);
      this.area = area;
      this.dirty = false;
      this.drawn = 0;
      allPlots.push(this);
      new ResizeObserver(() => {
        const w = area.clientWidth;
        if (w > 0 && Math.abs(w - this.u.width) > 2) this.u.setSize({ width: w, height: this.u.height });
      }).observe(area);
    }
    // points closer than `res` seconds share one (the newer values win): a 100 Hz stream is
    // drawn at 25 points a second, as much as a plot's width shows
    push(t, values) {
      const d = this.data, last = d[0].length - 1;
      if (last >= 0 && t - d[0][last] < this.res) {
        for (let i = 0; i < this.n; i++) if (values[i] !== null && values[i] !== undefined) d[i + 1][last] = values[i];
      } else {
        d[0].push(t);
        for (let i = 0; i < this.n; i++) d[i + 1].push(values[i] ?? null);
      }
      this.dirty = true;
    }
    // a plot repaints at most PLOT_FPS times a second: live enough, and the page stays free to
    // take the next updates at once (software rendering on a small machine)
    due(now) { return this.dirty && !this.paused && now - this.drawn >= 1 / PLOT_FPS; }
    draw(now) {
      this.drawn = now;
      if (!this.rolling) { this.u.setData(this.data, true); this.dirty = false; return; }
      const d = this.data, cut = now - this.window;
      let k = 0;
      while (k < d[0].length && d[0][k] < cut) k++;
      if (d[0].length - k > this.max) k = d[0].length - this.max;
      if (k > 0) for (const col of d) col.splice(0, k);
      this.u.setData(d, false);
      this.u.setScale("x", { min: now - this.window, max: now });
      this.dirty = false;
    }
    // a paused plot keeps its data coming but is no longer redrawn; a drag over it zooms in
    // (and pauses it), a double click shows everything it holds; live again: the rolling window
    pause(on) { this.paused = on; if (!on) { this.dirty = true; } if (this.onpause) this.onpause(on); }
    zoomTo(u) {
      const sel = u.select;
      if (!sel || sel.width < 3) return;
      const min = u.posToVal(sel.left, "x"), max = u.posToVal(sel.left + sel.width, "x");
      this.pause(true);
      u.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
      u.setScale("x", { min, max });
    }
    // the points shown (the x range of the view): [t, v1, v2, ...] rows
    shown() {
      const d = this.data, x = this.u.scales.x, lo = x.min ?? -Infinity, hi = x.max ?? Infinity, out = [];
      for (let k = 0; k < d[0].length; k++) if (d[0][k] >= lo && d[0][k] <= hi) out.push(d.map(col => col[k]));
      return out;
    }
    csv(labels) {
      const esc = (v) => /[",\n]/.test(v) ? `"${v.replace(/"/g, '""')}"` : v;
      const lines = [["time", "t", ...labels].map(esc).join(",")];
      for (const [t, ...vs] of this.shown())
        lines.push([new Date(t * 1000).toISOString(), t.toFixed(3), ...vs.map(v => v === null || v === undefined ? "" : String(v))].join(","));
      return lines.join("\n") + "\n";
    }
    // the plot as a PNG (a data URL): its title and keys above the canvas uPlot draws
    png(title, series) {
      const src = this.u.ctx.canvas, k = src.width / Math.max(1, this.u.width), head = Math.round(26 * k);
      const c = document.createElement("canvas");
      c.width = src.width; c.height = src.height + head;
      const g = c.getContext("2d");
      g.fillStyle = getComputedStyle(document.body).backgroundColor || "#0f1419";
      g.fillRect(0, 0, c.width, c.height);
      g.font = `${Math.round(13 * k)}px sans-serif`; g.textBaseline = "middle";
      g.fillStyle = "#e6edf3"; g.fillText(title, 8 * k, head / 2);
      let x = 16 * k + g.measureText(title).width;
      for (const s of series) {
        g.fillStyle = s.color; g.fillRect(x, head / 2 - 4 * k, 10 * k, 8 * k); x += 14 * k;
        g.fillStyle = "#8b9bab"; g.fillText(s.label, x, head / 2); x += g.measureText(s.label).width + 12 * k;
      }
      g.drawImage(src, 0, head);
      return c.toDataURL("image/png");
    }
  }
  // the text of the file chosen in a file input (null, said, when none is chosen)
  function readFile(input, hint) {
    return new Promise((resolve) => {
      const f = input.files[0];
      if (!f) { toast(hint); resolve(null); return; }
      const rd = new FileReader();
      rd.onload = () => resolve({ name: f.name, text: rd.result });
      rd.readAsText(f);
    });
  }
  // a file the browser saves: text, or a data URL
  function download(name, content, type = "text/plain") {
    const url = content.startsWith && content.startsWith("data:") ? content : URL.createObjectURL(new Blob([content], { type }));
    const a = el("a", { href: url, download: name });
    document.body.append(a); a.click(); a.remove();
    if (!url.startsWith("data:")) setTimeout(() => URL.revokeObjectURL(url), 10000);
  }

  // repaint at most once per frame; record how late the newest sample is drawn
  const painters = [];
  const PAINT_FPS = 15;           // figures and tables repaint at most this often
  let painted = 0;
  let newest = 0;
  function onFrame(fn) { painters.push(fn); }
  function sawSample(w) { if (w > newest) newest = w; }
  function frame() {
    const now = Date.now();
    drawOnePlot(now / 1000);
    if (now - painted >= 1000 / PAINT_FPS) { painted = now; for (const fn of painters) fn(now / 1000); }
    if (newest) { keep(stats.renderLatencies, Date.now() - newest); newest = 0; }
    requestAnimationFrame(frame);
  }
  requestAnimationFrame(frame);

  // a number field that sends on Enter or change, and a slider that sends while dragged (throttled)
  function throttle(fn, ms) {
    let last = 0, timer = null, args = null;
    return (...a) => {
      args = a;
      const now = Date.now(), wait = last + ms - now;
      if (wait <= 0) { last = now; fn(...args); }
      else if (!timer) timer = setTimeout(() => { timer = null; last = Date.now(); fn(...args); }, wait);
    };
  }

  function name() {
    const n = prompt("A name for this page (shown to the other pages):", localStorage.getItem("zkzap-name") || "");
    if (n === null) return;
    localStorage.setItem("zkzap-name", n.trim());
    send("hello", { name: n.trim() });
  }

  window.addEventListener("error", () => { stats.errors++; });
  const nm = $("#name");
  if (nm) nm.addEventListener("click", name);

  return { $, el, fmt, clock, setText, setClass, connect, request, send, toast, banner, controlling, Plot, onFrame, sawSample,
           throttle, stats, on, every, download, readFile, get hello() { return hello; }, renderControl,
           choose, mine, get buses() { return buses; }, get bus() { return chosen; } };
})();
