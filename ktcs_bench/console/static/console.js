// ktcs-bench CTC console: draws the CTC's state on the diagram, sends the operator's requests.
// Plain JS, no build step. Server messages: hello, state, trains, log, result, busy, frames,
// speed.
"use strict";

const ui = {
  ws: null, tool: "route", entry: null, stations: {}, nextId: 1,
  taps: [], trains: [], intervals: {},
};
const $ = (sel) => document.querySelector(sel);
const NS = "http://www.w3.org/2000/svg";

function send(msg) {
  if (ui.ws && ui.ws.readyState === WebSocket.OPEN) ui.ws.send(JSON.stringify(msg));
}

function request(msg) {
  msg.id = ui.nextId++;
  showResult("pending", "sent: " + describe(msg));
  send(msg);
}

function describe(m) {
  if (m.type === "route_set") return `station ${m.station}: set route ${m.entry}-${m.exit}`;
  if (m.type === "route_cancel") return `station ${m.station}: cancel route from ${m.entry}`;
  if (m.type === "point") return `station ${m.station}: point ${m.point} to ${m.position}`;
  if (m.type === "mode") return `station ${m.station}: ${m.mode} mode`;
  if (m.type === "ars") return `station ${m.station}: ARS ${m.on ? "on" : "off"}`;
  if (m.type === "direction") return `station ${m.station}: ask for interval ${m.interval}`;
  return m.type;
}

function showResult(kind, text) {
  const r = $("#result");
  r.className = kind;
  r.textContent = text;
}

// ---------------------------------------------------------------- tools and clicks

const HINTS = {
  route: "Set route: click an entry signal.",
  cancel: "Cancel route: click the entry signal of a set route.",
  normal: "Point N: click a point to move it to normal.",
  reverse: "Point R: click a point to move it to reverse.",
};

function setTool(tool) {
  ui.tool = tool;
  clearEntry();
  document.querySelectorAll("#tools button").forEach((b) =>
    b.classList.toggle("active", b.dataset.tool === tool));
  $("#hint").textContent = HINTS[tool];
}

function clearEntry() {
  if (ui.entry) ui.entry.el.classList.remove("selected");
  ui.entry = null;
}

function onSignal(el) {
  const station = Number(el.dataset.station), signal = el.dataset.signal;
  if (ui.tool === "cancel") {
    request({ type: "route_cancel", station, entry: signal });
    return;
  }
  if (ui.tool !== "route") return;
  if (!ui.entry) {
    if (el.dataset.kind === "marker") {
      showResult("error", `signal ${signal} is an exit marker, not an entry`);
      return;
    }
    ui.entry = { el, station, signal };
    el.classList.add("selected");
    $("#hint").textContent = `Entry ${station}/${signal} selected: click the exit signal (Esc to drop).`;
    return;
  }
  if (ui.entry.el === el) { clearEntry(); setTool("route"); return; }
  if (ui.entry.station !== station) {
    showResult("error", "entry and exit must be in the same station");
    return;
  }
  request({ type: "route_set", station, entry: ui.entry.signal, exit: signal });
  clearEntry();
  $("#hint").textContent = HINTS.route;
}

function onPoint(el) {
  if (ui.tool !== "normal" && ui.tool !== "reverse") {
    showResult("error", "choose Point N or Point R first");
    return;
  }
  request({ type: "point", station: Number(el.dataset.station), point: el.dataset.point,
            position: ui.tool });
}

// a click on an interval's arrow: the end that does not hold its permission asks for it (SPEC
// §6.6, `ctc direction ST INTERVAL`); with no end holding it there is nobody to ask
function onInterval(el) {
  const name = el.dataset.interval, iv = ui.intervals[name];
  if (!iv) {
    showResult("error", `interval ${name}: nothing known of it yet`);
    return;
  }
  const station = iv.holder === iv.west ? iv.east : iv.holder === iv.east ? iv.west : null;
  if (station === null) {
    showResult("error", `interval ${name}: no end holds its permission, nothing to ask for`);
    return;
  }
  request({ type: "direction", station, interval: name });
}

async function loadDiagram() {
  const res = await fetch("/diagram.svg");
  $("#diagram-wrap").innerHTML = await res.text();
  document.querySelectorAll("#diagram .signal").forEach((el) =>
    el.addEventListener("click", () => onSignal(el)));
  document.querySelectorAll("#diagram .point").forEach((el) =>
    el.addEventListener("click", () => onPoint(el)));
  document.querySelectorAll("#diagram .interval").forEach((el) =>
    el.addEventListener("click", () => onInterval(el)));
  if (ui.lastState) applyState(ui.lastState);
  if (ui.lastTrains) applyTrains(ui.lastTrains);
}

// ---------------------------------------------------------------- state onto the diagram

function stationCard(n) {
  let card = document.getElementById("card-" + n);
  if (card) return card;
  card = document.createElement("div");
  card.className = "st-card";
  card.id = "card-" + n;
  card.innerHTML = `<b></b><span class="badge mode"></span><span class="badge link"></span>
    <button data-mode="center">Center</button><button data-mode="local">Local</button>
    <button class="ars" hidden title="automatic route setting: click to switch"></button>`;
  card.querySelectorAll("button[data-mode]").forEach((b) => b.addEventListener("click", () =>
    request({ type: "mode", station: n, mode: b.dataset.mode })));
  const ars = card.querySelector("button.ars");
  ars.addEventListener("click", () =>
    request({ type: "ars", station: n, on: ars.dataset.on !== "true" }));
  $("#stations").appendChild(card);
  return card;
}

const POINT_TEXT = { normal: " N", reverse: " R", to_normal: " →N", to_reverse: " →R",
                     failed: " F", unknown: " ?" };

function applyState(stations) {
  ui.lastState = stations;
  for (const [n, st] of Object.entries(stations)) {
    const linkText = st.connected ? (st.synced ? "link up" : "link up, syncing") : "link down";
    const card = stationCard(Number(n));
    card.querySelector("b").textContent = st.name;
    const mode = card.querySelector(".mode");
    mode.textContent = st.mode;
    mode.className = "badge mode " + st.mode;
    const link = card.querySelector(".link");
    link.textContent = linkText;
    link.className = "badge link " + (st.connected ? "up" : "down");
    const g = document.getElementById("st-" + n);
    if (g) {
      const m = g.querySelector(".st-mode");
      m.textContent = st.mode + " mode";
      m.setAttribute("class", "st-mode " + st.mode);
      const l = g.querySelector(".st-link");
      l.textContent = linkText;
      l.setAttribute("class", "st-link " + (st.connected ? "up" : "down"));
      g.dataset.mode = st.mode;
      g.dataset.link = st.connected ? "up" : "down";
    }
    const live = st.connected && st.synced;
    for (const [tc, s] of Object.entries(st.track_circuits)) {
      document.querySelectorAll(`#diagram [data-tc="${tc}"]`).forEach((el) => {
        el.classList.toggle("unknown", !live || s.occupied === null);
        el.classList.toggle("occupied", live && s.occupied === true);
        el.classList.toggle("locked", live && s.locked && !s.occupied);
      });
    }
    for (const [p, s] of Object.entries(st.points)) {
      const el = document.getElementById(`pt-${n}-${p}`);
      if (!el) continue;
      const cls = ["point", s.position.replace("to_", "moving-to-")];
      if (s.moving) cls.push("moving");
      if (s.locked) cls.push("locked");
      if (s.position === "reverse") cls.push("reverse");
      if (s.position === "normal") cls.push("normal");
      if (s.position === "failed") cls.push("failed");
      el.setAttribute("class", cls.join(" "));
      el.dataset.position = s.position;
      el.querySelector(".pt-state").textContent = POINT_TEXT[s.position] || "";
      // the leg the point does not lie for is drawn dim, whatever its track circuit shows
      const lying = s.position.endsWith("reverse") ? "reverse" : "normal";
      document.querySelectorAll(`#diagram .tc[data-station="${n}"][data-point="${p}"]`)
        .forEach((d) => d.classList.toggle("inactive", d.dataset.leg !== lying));
    }
    for (const [name, s] of Object.entries(st.signals)) {
      const el = document.getElementById(`sig-${n}-${name}`);
      if (!el) continue;
      el.classList.forEach((c) => { if (c.startsWith("aspect-")) el.classList.remove(c); });
      if (s.aspect && live) el.classList.add("aspect-" + s.aspect);
      el.classList.toggle("held", !!s.held);
      el.classList.toggle("lamp-failed", !!s.lamp_failed);
      el.dataset.aspect = live && s.aspect ? s.aspect : "";
    }
    // each interval read from both its stations (ctc.model.IntervalReading): the arrow keeps
    // the head of the permission's direction, a dashed shaft alone when there is none
    for (const [name, iv] of Object.entries(st.intervals || {})) {
      ui.intervals[name] = iv;
      const g = document.getElementById(`iv-${name}`);
      if (!g) continue;
      const d = iv.direction === "up" || iv.direction === "down" ? iv.direction : "none";
      g.classList.remove("up", "down", "none", "disagree");
      g.classList.add(iv.direction === "disagree" ? "disagree" : d);
      g.dataset.direction = d === "none" ? "" : d;
      g.dataset.holder = iv.holder == null ? "" : String(iv.holder);
      const words = [];
      if (iv.direction === "disagree") words.push("ends disagree");
      if (iv.holder != null) words.push(`held by ${iv.holder}`);
      else if (d === "none") words.push("no direction");
      if (iv.asking && iv.asking.length) words.push(`asked by ${iv.asking.join(", ")}`);
      g.querySelector(".iv-dir").textContent = words.join(", ");
      g.querySelector("title")?.remove();
      const title = document.createElementNS("http://www.w3.org/2000/svg", "title");
      title.textContent = iv.text;
      g.appendChild(title);
    }
  }
}

// ARS per station (null: the CTC runs no timetable, no button)
function applyArs(ars) {
  for (const [n, on] of Object.entries(ars || {})) {
    const b = stationCard(Number(n)).querySelector("button.ars");
    b.hidden = false;
    b.dataset.on = on ? "true" : "false";
    b.textContent = on ? "ARS on" : "ARS off";
    b.className = "ars " + (on ? "on" : "off");
  }
}

// ---------------------------------------------------------------- trains on the diagram

// each train where the console placed it (its rear to its front on its track), its number at
// its front; a train no longer reported is taken off
function applyTrains(trains) {
  ui.lastTrains = trains;
  const layer = document.getElementById("trains");
  if (!layer) return;
  const seen = new Set();
  for (const t of trains) {
    seen.add(t.train);
    let g = layer.querySelector(`g.train[data-train="${CSS.escape(t.train)}"]`);
    if (!g) {
      g = svgEl("g", { class: "train", "data-train": t.train });
      g.appendChild(svgEl("line", { class: "train-body" }));
      g.appendChild(svgEl("circle", { class: "train-head", r: 4 }));
      g.appendChild(svgEl("text", { class: "train-label" }, t.train));
      layer.appendChild(g);
    }
    const [body, head, label] = g.childNodes;
    for (const [k, v] of Object.entries({ x1: t.tail_x, y1: t.y, x2: t.head_x, y2: t.y }))
      body.setAttribute(k, v);
    head.setAttribute("cx", t.head_x);
    head.setAttribute("cy", t.y);
    label.setAttribute("x", t.head_x);
    label.setAttribute("y", t.y - 20);
    g.dataset.headM = t.head_m;
    g.dataset.state = t.state || "";
    const title = `train ${t.train}: front ${t.head_m.toFixed(0)} m, ` +
      `${t.speed_kmh.toFixed(0)} km/h` + (t.state ? `, ${t.state}` : "");
    let tip = g.querySelector("title");
    if (!tip) { tip = svgEl("title", {}); g.appendChild(tip); }
    tip.textContent = title;
  }
  layer.querySelectorAll("g.train").forEach((g) => { if (!seen.has(g.dataset.train)) g.remove(); });
}

// ---------------------------------------------------------------- log

function addLog(entry) {
  const div = document.createElement("div");
  div.className = `entry ${entry.level} from-${entry.source || "console"}`;
  div.textContent = `${entry.time} ${entry.text}`;
  const log = $("#log");
  log.insertBefore(div, log.firstChild);
  while (log.childNodes.length > 300) log.removeChild(log.lastChild);
}

// ---------------------------------------------------------------- link monitor

function setupTaps(taps) {
  ui.taps = taps;
  const sel = $("#tap-select");
  sel.innerHTML = "";
  if (!taps.length) {
    sel.style.display = "none";
    $("#monitor-frames").innerHTML = '<div class="empty">No taps: the console was given no tap addresses.</div>';
    return;
  }
  sel.style.display = "";
  sel.appendChild(new Option("— choose a tap —", ""));
  taps.forEach((t, i) => sel.appendChild(new Option(t, String(i))));
  $("#monitor-frames").innerHTML = '<div class="empty">Choose a tap to watch its link.</div>';
  sel.onchange = () => {
    $("#monitor-frames").innerHTML = "";
    send({ type: "monitor", tap: sel.value === "" ? null : Number(sel.value) });
  };
}

function onFrames(msg) {
  const box = $("#monitor-frames");
  if (msg.reset) box.innerHTML = "";
  $("#monitor-status").textContent = msg.status || "";
  for (const e of msg.entries) {
    const pre = document.createElement("pre");
    pre.className = e.ok ? "good" : "bad";
    pre.textContent = e.text;
    box.insertBefore(pre, box.firstChild);
  }
  while (box.childNodes.length > 60) box.removeChild(box.lastChild);
}

// ---------------------------------------------------------------- speed–distance

function setupTrains(trains) {
  ui.trains = trains;
  const sel = $("#train-select");
  sel.innerHTML = "";
  if (!trains.length) {
    sel.style.display = "none";
    $("#speed-status").innerHTML = '<span class="empty">No train registered.</span>';
    return;
  }
  sel.style.display = "";
  sel.appendChild(new Option("— choose a train —", ""));
  trains.forEach((t) => sel.appendChild(new Option(t, t)));
  sel.onchange = () => send({ type: "train", train: sel.value || null });
  // a lab with trains shows the first one's panel at once (a living railway, not a blank panel)
  sel.value = trains[0];
  $("#speed-status").textContent = `train ${trains[0]}: waiting for data`;
  send({ type: "train", train: trains[0] });
}

function svgEl(tag, attrs, text) {
  const el = document.createElementNS(NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, v);
  if (text !== undefined) el.textContent = text;
  return el;
}

function onSpeed(msg) {
  const plot = $("#speed-plot");
  plot.innerHTML = "";
  const d = msg.data;
  if (!d) { $("#speed-status").textContent = `train ${msg.train}: no data`; return; }
  $("#speed-status").textContent =
    `train ${d.train}: front ${d.front_m.toFixed(1)} m, ${d.speed_kmh.toFixed(1)} km/h, ` +
    `status ${d.status}` + (d.target_m !== null ? `, target ${d.target_m.toFixed(0)} m` : "");
  const W = 560, H = 260, L = 34, R = 8, T = 8, B = 22;
  const x0 = d.x[0], x1 = d.x[d.x.length - 1];
  let vmax = d.speed_kmh;
  for (const c of Object.values(d.curves)) for (const v of c) if (v !== null) vmax = Math.max(vmax, v);
  vmax = Math.ceil((vmax * 1.1 + 5) / 10) * 10;
  const sx = (x) => L + (x - x0) / Math.max(1, x1 - x0) * (W - L - R);
  const sy = (v) => H - B - Math.min(v, vmax) / vmax * (H - T - B);
  plot.appendChild(svgEl("line", { class: "axis", x1: L, y1: H - B, x2: W - R, y2: H - B }));
  plot.appendChild(svgEl("line", { class: "axis", x1: L, y1: T, x2: L, y2: H - B }));
  for (let v = 0; v <= vmax; v += vmax > 100 ? 40 : 20)
    plot.appendChild(svgEl("text", { x: L - 4, y: sy(v) + 3, "text-anchor": "end" }, String(v)));
  plot.appendChild(svgEl("text", { x: L, y: H - 6, "text-anchor": "start" }, `${x0.toFixed(0)} m`));
  plot.appendChild(svgEl("text", { x: W - R, y: H - 6, "text-anchor": "end" }, `${x1.toFixed(0)} m`));
  let lx = L + 40;
  for (const name of ["mrsp", "ebi", "sbi", "permitted"]) {
    const pts = [];
    d.curves[name].forEach((v, i) => { pts.push(`${sx(d.x[i]).toFixed(1)},${sy(v === null ? vmax : v).toFixed(1)}`); });
    plot.appendChild(svgEl("polyline", { class: "c-" + name, "data-curve": name, points: pts.join(" ") }));
    plot.appendChild(svgEl("text", { x: lx, y: T + 10, class: "legend-" + name }, name.toUpperCase()));
    lx += 70;
  }
  plot.appendChild(svgEl("circle", { class: "actual", cx: sx(d.front_m), cy: sy(d.speed_kmh), r: 4 }));
  plot.appendChild(svgEl("text", { x: lx, y: T + 10 }, "● actual"));
}

// ---------------------------------------------------------------- websocket

function connect() {
  const ws = new WebSocket(`ws://${location.host}/ws`);
  ui.ws = ws;
  ws.onopen = () => { $("#conn").textContent = "console connected"; $("#conn").className = "up"; };
  ws.onclose = () => {
    $("#conn").textContent = "console disconnected — retrying";
    $("#conn").className = "down";
    setTimeout(connect, 1000);
  };
  ws.onmessage = (ev) => {
    const msg = JSON.parse(ev.data);
    if (msg.type === "hello") {
      $("#line-name").textContent = "— line " + msg.line;
      $("#log").innerHTML = "";
      msg.log.forEach(addLog);
      setupTaps(msg.taps);
      setupTrains(msg.trains);
    } else if (msg.type === "state") {
      applyState(msg.stations);
      applyArs(msg.ars);
    } else if (msg.type === "trains") {
      applyTrains(msg.trains);
    } else if (msg.type === "log") {
      addLog(msg.entry);
    } else if (msg.type === "result") {
      showResult(msg.ok ? "ok" : "error", msg.text);
    } else if (msg.type === "busy") {  // not sent: the console is bounding its work (try again)
      showResult("busy", msg.text);
    } else if (msg.type === "frames") {
      onFrames(msg);
    } else if (msg.type === "speed") {
      onSpeed(msg);
    }
  };
}

document.querySelectorAll("#tools button").forEach((b) =>
  b.addEventListener("click", () => setTool(b.dataset.tool)));
document.addEventListener("keydown", (e) => { if (e.key === "Escape") setTool(ui.tool); });
loadDiagram();
connect();
