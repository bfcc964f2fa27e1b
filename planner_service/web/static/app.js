// Live map of the UAV fleet: reads snapshots from /api/picture and /api/stream (SSE)
// and draws them as an SVG in local metres (x east, y north) plus a side panel.
// Every string in a snapshot comes from the network: it is only ever inserted with
// textContent or setAttribute, never parsed as HTML.
"use strict";

const SVG_NS = "http://www.w3.org/2000/svg";
// Vehicle colours; no red (alarms), grey (stale) or the user-state colours.
const PALETTE = ["#1565c0", "#8e24aa", "#00897b", "#c2185b", "#5d4037", "#3949ab",
  "#7cb342", "#00acc1", "#6d4c41", "#f4511e"];
const STALE_AFTER_S = 3;   // a vehicle whose status is older is drawn grey
const MIN_VIEW_M = 200;    // the fitted view is at least this wide and high
const MAX_TILES = 64;
const EARTH_R = 6378137;   // WGS84 equatorial radius, m
const COMMAND_HEADERS = {"Content-Type": "application/json", "X-Requested-With": "uavmec-live-map"};

const $ = (id) => document.getElementById(id);
const layer = (name) => $(`layer-${name}`);

const st = {
  picture: null,     // last snapshot
  receivedAt: 0,     // performance.now() at its receipt
  stream: null,      // the EventSource
  streamRetryMs: 250,  // delay before asking /api/picture after the stream gave up; doubles
  view: null,        // wanted world box {x0, y0, x1, y1} in metres, y north
  display: null,     // the view widened to the element's aspect ratio, + metres per pixel
  manual: false,     // the operator panned or zoomed: stop growing the view by itself
  frameQueued: false,
  tiles: new Map(),  // key -> <image>, kept across renders so that tiles do not flicker
};
window.livePicture = null;

// ---------------------------------------------------------------- small helpers
function svg(tag, attrs, parent) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [k, v] of Object.entries(attrs)) el.setAttribute(k, String(v));
  if (parent) parent.appendChild(el);
  return el;
}
function html(tag, className, text, parent) {
  const el = document.createElement(tag);
  if (className) el.className = className;
  if (text != null) el.textContent = text;
  if (parent) parent.appendChild(el);
  return el;
}
const finite = (...xs) => xs.every((x) => typeof x === "number" && Number.isFinite(x));
const fmt = (v, digits = 0, unit = "") => (finite(v) ? v.toFixed(digits) + unit : "?");
const points = (xy) => xy.map(([x, y]) => `${x},${-y}`).join(" ");  // SVG y grows southward
const byId = (a, b) => a.id.localeCompare(b.id, undefined, {numeric: true});
const clock = (t) => (finite(t) ? new Date(t * 1000).toTimeString().slice(0, 8) : "?");

// ---------------------------------------------------------------- network
async function start() {
  let r;
  try {
    r = await fetch("/api/picture", {credentials: "same-origin", cache: "no-store"});
  } catch (e) {
    return retryLater("connection lost, retrying");
  }
  if (r.status === 401) return showLogin();
  if (!r.ok) return retryLater(`server answered ${r.status}, retrying`);
  showLive();
  receive(await r.json());
  openStream();
}

function retryLater(text) {
  setConnection("lost", text);
  setTimeout(start, 3000);
}

function openStream() {
  if (st.stream) st.stream.close();
  const es = new EventSource("/api/stream");  // same origin: the session cookie goes along
  st.stream = es;
  es.onopen = () => { st.streamRetryMs = 250; setConnection("live", "live"); };
  es.addEventListener("picture", (ev) => {
    try { receive(JSON.parse(ev.data)); } catch (e) { console.warn("bad snapshot", e); }
  });
  es.onerror = () => {
    setConnection("lost", "connection lost, retrying");
    // EventSource retries by itself after a dropped connection, but gives up for good
    // (CLOSED) on an HTTP error such as 401: then /api/picture tells us why (soon, but
    // backing off so that a stream failing for another reason is not hammered).
    if (es.readyState === EventSource.CLOSED) {
      st.stream = null;
      setTimeout(start, st.streamRetryMs);
      st.streamRetryMs = Math.min(10000, st.streamRetryMs * 2);
    }
  };
}

function receive(picture) {
  st.picture = window.livePicture = picture;
  st.receivedAt = performance.now();
  scheduleRender();
}

function setConnection(state, text) {
  $("connection").dataset.state = state;
  $("connection").textContent = text;
}

function showLogin() {  // the live view holds no data while logged out
  if (st.stream) st.stream.close();
  st.stream = st.picture = window.livePicture = st.view = null;
  for (const name of ["tiles", "grid", "trails", "plans", "users", "vehicles"]) layer(name).replaceChildren();
  st.tiles.clear();
  for (const el of [$("cards"), $("alerts"), document.querySelector("#users tbody")]) el.replaceChildren();
  $("live").hidden = $("status").hidden = true;
  $("login").hidden = false;
  $("token").focus();
}

function showLive() {
  $("login").hidden = true;
  $("live").hidden = $("status").hidden = false;
}

async function login(ev) {
  ev.preventDefault();  // a fetch keeps a wrong token's 401 on this page
  const body = new URLSearchParams({token: $("token").value});
  try {
    // The server answers 303 to / and fetch follows it: ok means the cookie is set.
    const r = await fetch("/login", {method: "POST", body, credentials: "same-origin"});
    if (!r.ok) throw new Error((await r.json().catch(() => ({}))).error || `HTTP ${r.status}`);
  } catch (e) {
    $("login-error").textContent = e.message;
    return;
  }
  $("token").value = $("login-error").textContent = "";
  start();
}

async function command(id, cmd, card) {
  const buttons = card.querySelectorAll("button");
  const answer = card.querySelector(".answer");
  buttons.forEach((b) => { b.disabled = true; });  // one command in flight per vehicle
  answer.className = "answer pending";
  answer.textContent = `${cmd}...`;
  let kind = "error", text;
  try {
    const r = await fetch(`/api/vehicles/${encodeURIComponent(id)}/${cmd}`, {
      method: "POST", credentials: "same-origin", headers: COMMAND_HEADERS,
      body: JSON.stringify({reason: "from the live map"}),
    });
    const body = await r.json().catch(() => ({}));
    if (r.ok && typeof body.accepted === "boolean") kind = body.accepted ? "accepted" : "refused";
    text = kind === "error" ? body.error || `HTTP ${r.status}` : body.message ?? "";
    if (r.status === 401) start();
  } catch (e) {
    text = e.message;
  }
  buttons.forEach((b) => { b.disabled = false; });
  answer.className = `answer ${kind}`;
  answer.textContent = `${kind}: ${text}`;
}

// ---------------------------------------------------------------- rendering
function scheduleRender() {  // at most one render per animation frame
  if (st.frameQueued) return;
  st.frameQueued = true;
  requestAnimationFrame(() => { st.frameQueued = false; render(); });
}

function render() {
  const p = st.picture;
  if (!p) return;
  const ids = (p.vehicles || []).slice().sort(byId).map((v) => v.id);
  const colours = new Map(ids.map((id, i) => [id, PALETTE[i % PALETTE.length]]));
  const alarmed = alarmedVehicles(p, ids);
  renderHeader(p);
  renderAlerts(p.alerts || []);
  renderMap(p, colours, alarmed);
  renderPanel(p, colours, alarmed);
  document.body.dataset.version = String(p.version);
}

// Vehicles named by an alert or by a lost separation pair ("uav1-uav2: ...").
function alarmedVehicles(p, ids) {
  const out = new Set((p.alerts || []).map((a) => a.vehicle).filter(Boolean));
  for (const c of p.separation?.conflicts || []) {
    const pair = String(c).split(":")[0];
    for (const id of ids) if (pair.startsWith(`${id}-`) || pair.endsWith(`-${id}`)) out.add(id);
  }
  return out;
}

function renderHeader(p) {
  $("prefix").textContent = p.prefix ?? "";
  const s = p.separation || {state: "unknown"};
  const el = $("separation");
  el.dataset.state = s.state;
  el.textContent = {
    ok: "separation ok",
    lost: `SEPARATION LOST: ${(s.conflicts || []).join("; ")}`,
    unknown: `separation unknown${s.unknown?.length ? ": " + s.unknown.join("; ") : ""}`,
    none: "separation: not applicable",
  }[s.state] ?? `separation: ${s.state}`;
  el.title = s.closest ? `closest: ${s.closest}` : "";
  $("footer-info").textContent = `version ${p.version}` + (p.ignored ? `, ${p.ignored} messages ignored` : "");
  updateAge();
}

function updateAge() {
  if (!st.picture) return;
  const age = (performance.now() - st.receivedAt) / 1000;
  $("age").textContent = `updated ${age.toFixed(1)} s ago`;
  $("age").classList.toggle("old", age > 5);
}

function renderAlerts(alerts) {
  $("alerts").replaceChildren(...alerts.map((a) => html("div", `alert alert-${a.severity === "error" ? "error" : "warning"}`,
    a.vehicle ? `${a.vehicle}: ${a.text}` : a.text)));
  $("alerts").hidden = alerts.length === 0;
}

// ---- view box
function contentBounds(p) {
  const b = {x0: Infinity, y0: Infinity, x1: -Infinity, y1: -Infinity};
  const add = (x, y) => {
    if (finite(x, y)) Object.assign(b, {x0: Math.min(b.x0, x), x1: Math.max(b.x1, x), y0: Math.min(b.y0, y), y1: Math.max(b.y1, y)});
  };
  for (const v of p.vehicles || []) {
    add(v.x_m, v.y_m);
    for (const [x, y] of v.trail || []) add(x, y);
    for (const q of v.plan?.points || []) add(q.x_m, q.y_m);
  }
  for (const u of p.users || []) add(u.x_m, u.y_m);
  return b.x0 <= b.x1 ? b : {x0: 0, y0: 0, x1: 0, y1: 0};
}

function padded(b) {  // 10% margin on each side, at least MIN_VIEW_M across
  const w = b.x1 - b.x0, h = b.y1 - b.y0;
  const mx = Math.max(0.1 * w, (MIN_VIEW_M - w) / 2), my = Math.max(0.1 * h, (MIN_VIEW_M - h) / 2);
  return {x0: b.x0 - mx, x1: b.x1 + mx, y0: b.y0 - my, y1: b.y1 + my};
}

// The view only grows (and only when something leaves it), so it never jumps about.
function updateView(p) {
  const b = contentBounds(p), v = st.view;
  if (!v) { st.view = padded(b); return; }
  if (st.manual || (b.x0 >= v.x0 && b.y0 >= v.y0 && b.x1 <= v.x1 && b.y1 <= v.y1)) return;
  const q = padded(b);
  st.view = {x0: Math.min(v.x0, q.x0), y0: Math.min(v.y0, q.y0), x1: Math.max(v.x1, q.x1), y1: Math.max(v.y1, q.y1)};
}

function displayBox() {  // the view widened to the element's shape, so that 1 m is 1 m both ways
  const el = $("map"), v = st.view;
  const W = el.clientWidth || 800, H = el.clientHeight || 600;
  let w = v.x1 - v.x0, h = v.y1 - v.y0;
  if (w / h > W / H) h = w * H / W; else w = h * W / H;
  const cx = (v.x0 + v.x1) / 2, cy = (v.y0 + v.y1) / 2;
  return {x0: cx - w / 2, x1: cx + w / 2, y0: cy - h / 2, y1: cy + h / 2, mpp: w / W};
}

// ---- map
function renderMap(p, colours, alarmed) {
  updateView(p);
  const d = st.display = displayBox();
  $("map").setAttribute("viewBox", `${d.x0} ${-d.y1} ${d.x1 - d.x0} ${d.y1 - d.y0}`);
  // Text sizes and halos in CSS are multiples of --px: one screen pixel in metres.
  $("world").style.setProperty("--px", String(d.mpp));
  renderTiles(p, d);
  renderGrid(d);
  renderScale(d);
  for (const name of ["trails", "plans", "users", "vehicles"]) layer(name).replaceChildren();
  for (const u of p.users || []) drawUser(u, d);
  for (const v of (p.vehicles || []).slice().sort(byId)) drawVehicle(v, colours.get(v.id), alarmed.has(v.id), d);
}

function label(text, x, y, cls, parent) {
  svg("text", {x, y: -y, class: `label ${cls}`}, parent).textContent = text;
}
const isStale = (v) => v.alive !== true || (finite(v.status_age_s) && v.status_age_s > STALE_AFTER_S);

function drawVehicle(v, colour, alarm, d) {
  const trail = (v.trail || []).filter(([x, y]) => finite(x, y));
  if (trail.length > 1) svg("polyline", {class: "trail", stroke: colour, points: points(trail)}, layer("trails"));
  drawPlan(v, colour, d);
  if (!finite(v.x_m, v.y_m)) return;
  const stale = isStale(v);
  const m = svg("circle", {
    class: `vehicle${stale ? " stale" : ""}${alarm || v.degraded ? " alarm" : ""}`,
    cx: v.x_m, cy: -v.y_m, r: 7 * d.mpp, fill: stale ? "#9e9e9e" : colour,
    "data-vehicle": v.id, "data-x": v.x_m, "data-y": v.y_m,
  }, layer("vehicles"));
  svg("title", {}, m).textContent = `${v.id}: ${v.phase ?? "?"}${v.degraded ? ", " + v.degraded : ""}`;
  label(`${v.id} ${fmt(v.z_m, 0, " m")}`, v.x_m + 10 * d.mpp, v.y_m + 4 * d.mpp, "vehicle-label", layer("vehicles"));
}

function drawPlan(v, colour, d) {
  const pts = v.plan?.points || [];
  if (!pts.length) return;
  const next = finite(v.plan.next) ? v.plan.next : pts.length;  // null: nothing left to fly
  const g = layer("plans");
  const xy = (q) => [q.x_m, q.y_m];
  if (next > 0) svg("polyline", {class: "plan-done", stroke: colour, points: points(pts.slice(0, next).map(xy))}, g);
  const ahead = pts.slice(next).map(xy);
  if (finite(v.x_m, v.y_m)) ahead.unshift([v.x_m, v.y_m]);
  if (ahead.length > 1) svg("polyline", {class: "plan", stroke: colour, points: points(ahead)}, g);
  pts.forEach((q, i) => {
    if (!finite(q.x_m, q.y_m)) return;
    const c = svg("circle", {
      class: `plan-point${i < next ? " done" : ""}${i === v.plan.next ? " next" : ""}`,
      cx: q.x_m, cy: -q.y_m, r: 4.5 * d.mpp, stroke: colour,
      "data-vehicle": v.id, "data-order": i + 1, "data-x": q.x_m, "data-y": q.y_m,
    }, g);
    svg("title", {}, c).textContent = `${v.id} point ${i + 1}${q.user_id ? " for " + q.user_id : ""}`;
    label(String(i + 1), q.x_m + 6 * d.mpp, q.y_m - 10 * d.mpp, `plan-label${i < next ? " done" : ""}`, g);
  });
}

function drawUser(u, d) {
  if (!finite(u.x_m, u.y_m)) return;
  const s = 9 * d.mpp;
  const r = svg("rect", {
    class: `user state-${u.state}`, x: u.x_m - s / 2, y: -u.y_m - s / 2, width: s, height: s,
    "data-user": u.id, "data-x": u.x_m, "data-y": u.y_m,
  }, layer("users"));
  svg("title", {}, r).textContent = `${u.id}: ${u.state}, backlog ${u.backlog}, served ${u.served_tasks}`;
  label(`${u.id} (${u.backlog})`, u.x_m + 7 * d.mpp, u.y_m - 4 * d.mpp, "user-label", layer("users"));
}

function renderGrid(d) {
  const g = layer("grid"), w = d.x1 - d.x0;
  let step = w < 400 ? 50 : w > 4000 ? 500 : 100;
  while (w / step > 60) step *= 10;  // very wide views: keep the line count sane
  g.replaceChildren();
  for (let k = Math.ceil(d.x0 / step); k * step <= d.x1; k++) {
    const x = k * step;
    svg("line", {class: x === 0 ? "grid axis" : "grid", x1: x, x2: x, y1: -d.y1, y2: -d.y0}, g);
    label(`${x} m`, x + 3 * d.mpp, d.y0 + 5 * d.mpp, "grid-label", g);
  }
  for (let k = Math.ceil(d.y0 / step); k * step <= d.y1; k++) {
    const y = k * step;
    svg("line", {class: y === 0 ? "grid axis" : "grid", x1: d.x0, x2: d.x1, y1: -y, y2: -y}, g);
    label(`${y} m`, d.x0 + 4 * d.mpp, y + 3 * d.mpp, "grid-label", g);
  }
}

function renderScale(d) {  // a 1-2-5 length at most 120 px long
  const want = 120 * d.mpp, p10 = 10 ** Math.floor(Math.log10(want));
  const len = [5, 2, 1].map((f) => f * p10).find((l) => l <= want);
  $("scale-bar").style.width = `${len / d.mpp}px`;
  $("scale-label").textContent = len >= 1000 ? `${len / 1000} km` : `${len} m`;
}

// Local XYZ tiles under the view: slippy-map tile corners in degrees, placed in local
// metres with the same equirectangular approximation around the origin as the server.
function renderTiles(p, d) {
  const o = p.frame?.origin, z = p.tiles?.zoom, want = new Set();
  if (o && finite(o.lat_deg, o.lon_deg) && Number.isInteger(z)) {
    const ky = EARTH_R * Math.PI / 180, kx = ky * Math.cos(o.lat_deg * Math.PI / 180);  // m per degree
    const n = 2 ** z, clamp = (i) => Math.min(n - 1, Math.max(0, i));
    const lonOf = (x) => x / n * 360 - 180;
    const latOf = (y) => Math.atan(Math.sinh(Math.PI * (1 - 2 * y / n))) * 180 / Math.PI;
    const tileX = (e) => clamp(Math.floor((o.lon_deg + e / kx + 180) / 360 * n));
    const tileY = (north) => {
      const r = (o.lat_deg + north / ky) * Math.PI / 180;
      return clamp(Math.floor((1 - Math.asinh(Math.tan(r)) / Math.PI) / 2 * n));
    };
    const xa = tileX(d.x0), xb = tileX(d.x1), ya = tileY(d.y1), yb = tileY(d.y0);  // tile y grows south
    if ((xb - xa + 1) * (yb - ya + 1) <= MAX_TILES) {
      for (let x = xa; x <= xb; x++) for (let y = ya; y <= yb; y++) {
        const key = `${z}/${x}/${y}@${o.lat_deg},${o.lon_deg}`;
        want.add(key);
        if (st.tiles.has(key)) continue;
        const e0 = (lonOf(x) - o.lon_deg) * kx, e1 = (lonOf(x + 1) - o.lon_deg) * kx;
        const nTop = (latOf(y) - o.lat_deg) * ky, nBottom = (latOf(y + 1) - o.lat_deg) * ky;
        st.tiles.set(key, svg("image", {
          href: `/tiles/${z}/${x}/${y}.png`, x: e0, y: -nTop, width: e1 - e0, height: nTop - nBottom,
          preserveAspectRatio: "none", class: "tile",
        }, layer("tiles")));
      }
    }
  }
  for (const [key, el] of st.tiles) if (!want.has(key)) { el.remove(); st.tiles.delete(key); }
}

// ---- side panel: cards are kept per vehicle, so that answers and disabled buttons survive renders
const FIELDS = [["status", "status", "wide"], ["layer"], ["phase"], ["mode"], ["armed"], ["battery"], ["authority"],
  ["position", "position ok"], ["mission"], ["requests", "requests", "wide"], ["next", "next", "wide"],
  ["waiting", "waiting for", "wide"], ["degraded", "degraded", "wide bad"]];

function makeCard(id) {
  const card = html("div", "vehicle-card");
  card.dataset.vehicle = id;
  const head = html("div", "card-head", null, card);
  html("span", "swatch", null, head);
  html("strong", null, id, head);
  const fields = html("div", "fields", null, card);
  for (const [key, name = key, cls = ""] of FIELDS) {
    const row = html("div", `row ${cls}`, null, fields);
    row.dataset.field = key;
    html("span", "k", `${name}: `, row);
    html("span", "v", "", row);
  }
  html("ul", "events", null, card);
  const bar = html("div", "buttons", null, card);
  for (const [cmd, text] of [["start", "Start"], ["hold", "Hold"]]) {
    const b = Object.assign(html("button", cmd, text, bar), {type: "button"});
    b.dataset.vehicle = id;
    b.addEventListener("click", () => command(id, cmd, card));
  }
  html("span", "answer", null, bar);
  return card;
}

function nextText(plan) {
  if (!plan || !finite(plan.next)) return "none";
  const q = plan.points?.[plan.next];
  return `point ${plan.next + 1}${q?.user_id ? " for " + q.user_id : ""}` +
    (finite(plan.eta_s) ? `, ETA ${Math.round(plan.eta_s)} s` : "");
}

function updateCard(card, v, colour, alarm) {
  const stale = isStale(v);
  card.classList.toggle("stale", stale);
  card.classList.toggle("alarm", alarm || Boolean(v.degraded));
  card.querySelector(".swatch").style.background = stale ? "#9e9e9e" : colour;
  const values = {
    status: `${v.alive === true ? "alive" : v.alive === false ? "not alive" : "unknown"}` +
      (finite(v.status_age_s) ? `, ${v.status_age_s.toFixed(1)} s old` : ""),
    layer: finite(v.layer_m) ? `${v.layer_m.toFixed(0)} m` : "none",
    phase: v.phase ?? "?",
    mode: v.mode ?? "?",
    armed: v.armed === true ? "yes" : v.armed === false ? "no" : "?",
    battery: finite(v.battery) ? `${Math.round(v.battery * 100)} %` + (v.battery_source ? ` (${v.battery_source})` : "") : "unknown",
    authority: v.authority ?? "?",
    position: v.position_ok ? "yes" : "NO",
    mission: `${v.mission_seq ?? "?"}/${v.mission_total ?? "?"}`,
    requests: `${v.pending_requests ?? "?"} pending, ${v.served_users ?? "?"} served`,
    next: nextText(v.plan),
    waiting: v.waiting_for || "",
    degraded: v.degraded || "",
  };
  for (const row of card.querySelectorAll(".row")) {
    const value = values[row.dataset.field];
    row.querySelector(".v").textContent = value;
    row.hidden = value === "";
  }
  card.querySelector('[data-field="authority"]').title = v.authority_detail || "";
  card.querySelector('[data-field="position"]').classList.toggle("bad", !v.position_ok);
  card.querySelector(".events").replaceChildren(...(v.events || []).slice(-3).map((e) =>
    html("li", null, `${clock(e.time_s)} ${e.event}${e.user_id ? " " + e.user_id : ""}${e.detail ? ": " + e.detail : ""}`)));
}

function renderPanel(p, colours, alarmed) {
  const box = $("cards"), seen = new Set();
  (p.vehicles || []).slice().sort(byId).forEach((v, i) => {
    seen.add(v.id);
    const card = [...box.children].find((c) => c.dataset.vehicle === v.id) || makeCard(v.id);
    if (box.children[i] !== card) box.insertBefore(card, box.children[i] || null);
    updateCard(card, v, colours.get(v.id), alarmed.has(v.id));
  });
  for (const card of [...box.children]) if (!seen.has(card.dataset.vehicle)) card.remove();

  const rows = (p.users || []).map((u) => {
    const tr = html("tr", "user-row");
    tr.dataset.user = u.id;
    [u.id, u.state, u.vehicle ?? "-", u.place ?? "-", finite(u.eta_s) ? `${Math.round(u.eta_s)} s` : "-", u.backlog,
      u.served_tasks].forEach((c, i) => html("td", i === 1 ? `state-${u.state}` : null, String(c ?? "?"), tr));
    return tr;
  });
  document.querySelector("#users tbody").replaceChildren(...rows);
}

// ---------------------------------------------------------------- pan and zoom
// Once the operator pans or zooms, the view stops growing by itself until "fit".
function setManualView(view) {
  st.view = view;
  st.manual = true;
  scheduleRender();
}

function initPanZoom() {
  const el = $("map");
  let drag = null;
  el.addEventListener("pointerdown", (e) => {
    if (!st.display) return;
    drag = {x: e.clientX, y: e.clientY, view: st.view, mpp: st.display.mpp};
    el.setPointerCapture(e.pointerId);
  });
  el.addEventListener("pointermove", (e) => {
    if (!drag) return;
    const v = drag.view, dx = (e.clientX - drag.x) * drag.mpp, dy = (e.clientY - drag.y) * drag.mpp;
    setManualView({x0: v.x0 - dx, x1: v.x1 - dx, y0: v.y0 + dy, y1: v.y1 + dy});
  });
  for (const type of ["pointerup", "pointercancel"]) el.addEventListener(type, () => { drag = null; });
  el.addEventListener("wheel", (e) => {  // zoom about the point under the cursor
    if (!st.display) return;
    e.preventDefault();
    const d = st.display, r = el.getBoundingClientRect();
    const wx = d.x0 + (e.clientX - r.left) * d.mpp, wy = d.y1 - (e.clientY - r.top) * d.mpp;
    const f = Math.exp(Math.max(-100, Math.min(100, e.deltaY)) * 0.002);
    setManualView({x0: wx + (d.x0 - wx) * f, x1: wx + (d.x1 - wx) * f, y0: wy + (d.y0 - wy) * f, y1: wy + (d.y1 - wy) * f});
  }, {passive: false});
}

// ---------------------------------------------------------------- start
$("login-form").addEventListener("submit", login);
$("fit").addEventListener("click", () => { st.view = null; st.manual = false; scheduleRender(); });
window.addEventListener("resize", scheduleRender);
setInterval(updateAge, 1000);
initPanZoom();
start();
