// The gateway's live page: the site from /v1/site, the alerts from /v1/alerts, the sensors'
// self-calibration from /v1/calibration, then the live stream /v1/stream (Server-Sent Events
// read with fetch, so that a key can go in a header).
//
// Frames: the site's road frame, station s [m] along the centerline in the direction of
// travel and offset d [m] from it, positive to the left. Both views straighten the road:
// travel runs left to right, the left side of the road is up.
//
// For tests and scripts: document.body.dataset.{connection, trackCount, alertCount,
// calibrationBumped} and window.wzLive {connection, batches, stamp, tracks: [{track_id, x_m,
// y_m, station_m, offset_m, speed_mps}], alerts: [alert_id, newest first], calibration:
// {sensor_id: {kind, state, yaw_deg, pitch_deg, clock_offset_ms, stale}}}.
"use strict";

(() => {
  const MPS_PER_MPH = 0.44704;
  const KEY_STORE = "wz-gateway-api-key";
  const TRAIL_S = 4.0; // seconds of trail behind each vehicle
  const STALE_AFTER_S = 3.0; // no track batch for this long: the data is stale
  const SILENT_STREAM_S = 45.0; // nothing at all (not even a heartbeat): reconnect
  const MAX_ALERTS = 200;
  const CALIBRATION_STALE_S = 30.0; // no calibration for this long: shown as old (greyed)
  const TABLE_ROWS = 8;
  const SIZES = { // default length and width [m] when the tracker gave none
    car: [4.6, 1.85], truck: [14.0, 2.55], bus: [12.0, 2.55], motorcycle: [2.2, 0.8],
    unknown: [4.6, 1.85],
  };
  const SPEED_COLORS = {
    slow: "#4aa3ff", ok: "#2ecc71", near: "#f5e04a", over: "#ff9f1a", critical: "#ff3b3b",
  };
  const AREA_STYLE = {
    advance_warning: { label: "Advance warning", color: "#f5e04a" },
    transition: { label: "Taper", color: "#f28c28" },
    buffer: { label: "Buffer", color: "#ffb35c" },
    activity: { label: "Work area", color: "#f26d21" },
    termination: { label: "Termination", color: "#c9a227" },
  };
  const ALERT_NAMES = {
    speeding: "Speeding", aggressive_approach: "Aggressive approach",
    queue_approach: "Approaching the queue too fast",
    hard_braking: "Hard braking", late_merge: "Late merge",
    short_ttc: "Short time to collision", intrusion: "Work-area intrusion", queue: "Queue",
  };

  const $ = (id) => document.getElementById(id);
  const live = {
    connection: "connecting", batches: 0, stamp: null, tracks: [], alerts: [], calibration: {},
  };
  window.wzLive = live;

  const state = {
    road: null, // built from the site, see buildRoad
    batch: null, // the newest tracks event's data
    batchAt: null, // performance.now() / 1000 when it came
    stampOffsetS: null, // wall clock minus capture stamp (simulation stamps start at 0)
    trails: new Map(), // track_id -> [{s, d, t}]
    alerts: [], // newest first
    alertIds: new Set(),
    calibration: new Map(), // sensor_id -> {kind, message (or null), receivedAt [performance s]}
    calibrationTick: null, // the second the calibration table was last drawn
    view: null, // plan view: {s, d, scale [px/m]}
    highlight: null, // {trackId, until}
    drawQueued: false,
  };

  class AuthError extends Error {}

  // --- HTTP -----------------------------------------------------------------------------

  function authHeaders() {
    const key = sessionStorage.getItem(KEY_STORE);
    return key ? { "X-API-Key": key } : {};
  }

  async function getJson(path) {
    const response = await fetch(path, { headers: authHeaders(), cache: "no-store" });
    if (response.status === 401 || response.status === 403) {
      askForKey();
      throw new AuthError(`${path}: HTTP ${response.status}`);
    }
    if (!response.ok) throw new Error(`${path}: HTTP ${response.status}`);
    return response.json();
  }

  const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

  function askForKey() {
    setConnection("unauthorized", "key needed");
    const dialog = $("key-dialog");
    if (!dialog.open) dialog.showModal();
  }

  // --- the stream -----------------------------------------------------------------------

  let lastEventId = null;
  let retryMs = 2000;

  async function follow() {
    for (;;) {
      const controller = new AbortController();
      let watchdog = null;
      const rearm = () => {
        clearTimeout(watchdog);
        watchdog = setTimeout(() => controller.abort(), SILENT_STREAM_S * 1000);
      };
      try {
        const headers = authHeaders();
        if (lastEventId) headers["Last-Event-ID"] = lastEventId;
        rearm();
        const response = await fetch("/v1/stream", {
          headers, cache: "no-store", signal: controller.signal,
        });
        if (response.status === 401 || response.status === 403) {
          clearTimeout(watchdog);
          askForKey();
          return; // a key reloads the page
        }
        if (!response.ok || !response.body) throw new Error(`HTTP ${response.status}`);
        setConnection("live");
        await readEvents(response.body, rearm);
      } catch (error) {
        // the connection failed or was aborted: say so below, then try again
      } finally {
        clearTimeout(watchdog);
      }
      setConnection("offline");
      await sleep(retryMs);
    }
  }

  async function readEvents(body, rearm) {
    const reader = body.pipeThrough(new TextDecoderStream()).getReader();
    let buffer = "";
    for (;;) {
      const { value, done } = await reader.read();
      if (done) return;
      rearm();
      buffer += value.replace(/\r\n?/g, "\n");
      let end;
      while ((end = buffer.indexOf("\n\n")) >= 0) {
        const block = buffer.slice(0, end);
        buffer = buffer.slice(end + 2);
        dispatch(block);
      }
    }
  }

  function dispatch(block) {
    let type = "message";
    const data = [];
    for (const line of block.split("\n")) {
      if (!line || line.startsWith(":")) continue; // a comment: the heartbeat
      const colon = line.indexOf(":");
      const field = colon < 0 ? line : line.slice(0, colon);
      let value = colon < 0 ? "" : line.slice(colon + 1);
      if (value.startsWith(" ")) value = value.slice(1);
      if (field === "event") type = value;
      else if (field === "data") data.push(value);
      else if (field === "id") lastEventId = value;
      else if (field === "retry" && /^\d+$/.test(value)) retryMs = Number(value);
    }
    if (!data.length) return;
    const payload = JSON.parse(data.join("\n"));
    if (type === "tracks") onTracks(payload);
    else if (type === "alert") onAlert(payload, true);
    else if (type === "calibration") onCalibration(payload, 0);
  }

  // --- connection and figures -----------------------------------------------------------

  function setConnection(connection, text) {
    live.connection = connection;
    document.body.dataset.connection = connection;
    $("connection-text").textContent = text || {
      live: "live", stale: "no data", offline: "offline", connecting: "connecting",
      unauthorized: "key needed",
    }[connection];
  }

  function tick() {
    const age = state.batchAt === null ? null : performance.now() / 1000 - state.batchAt;
    $("data-age").textContent = age === null ? "--" : age < 60 ? `${age.toFixed(1)} s` : "> 1 min";
    if (live.connection === "live" && (age === null || age > STALE_AFTER_S)) {
      setConnection("stale");
    } else if (live.connection === "stale" && age !== null && age <= STALE_AFTER_S) {
      setConnection("live");
    }
    const second = Math.floor(performance.now() / 1000);
    if (state.calibration.size && second !== state.calibrationTick) {
      state.calibrationTick = second; // ages and staleness move on
      renderCalibration();
    }
  }

  // --- the site -------------------------------------------------------------------------

  function buildRoad(site) {
    const points = site.centerline_xy_m;
    const stations = [0];
    for (let i = 1; i < points.length; i++) {
      const [x0, y0] = points[i - 1];
      const [x1, y1] = points[i];
      stations.push(stations[i - 1] + Math.hypot(x1 - x0, y1 - y0));
    }
    const lanes = [...site.lanes].sort((a, b) => a.index - b.index);
    const closed = lanes.find((lane) => lane.index === site.closed_lane_index);
    const others = lanes.filter((lane) => lane !== closed);
    const closedIsLeft = closed.center_offset_m >= Math.max(...others.map((l) => l.center_offset_m));
    const areas = {};
    for (const area of site.work_zone) areas[area.kind] = { start: area.start_station_m, end: area.end_station_m };
    const road = {
      site, points, stations, length: stations[stations.length - 1], lanes, closed,
      rightEdge: Math.min(...lanes.map((l) => l.center_offset_m - l.width_m / 2)),
      leftEdge: Math.max(...lanes.map((l) => l.center_offset_m + l.width_m / 2)),
      closedOuter: closedIsLeft ? closed.center_offset_m + closed.width_m / 2 : closed.center_offset_m - closed.width_m / 2,
      closedInner: closedIsLeft ? closed.center_offset_m - closed.width_m / 2 : closed.center_offset_m + closed.width_m / 2,
      areas,
      limits: [...site.speed_limits].sort((a, b) => a.start_station_m - b.start_station_m),
      marginMph: site.alerts.speeding.margin_mph,
      criticalMph: site.alerts.speeding.critical_excess_mph,
    };
    road.taperStart = areas.transition ? areas.transition.start : (areas.activity || { start: road.length / 2 }).start;
    road.zoneLimitMps = limitAt(road, road.taperStart);
    road.sensors = site.sensors.map((sensor) => {
      const { s, d } = project(road, sensor.pose.x_m, sensor.pose.y_m);
      const intrinsics = sensor.intrinsics;
      return {
        id: sensor.sensor_id, kind: intrinsics.kind, s, d,
        yaw: sensor.pose.yaw_deg * Math.PI / 180 - roadHeading(road, s),
        fov: (intrinsics.horizontal_fov_deg || 360) * Math.PI / 180,
        range: intrinsics.max_range_m || 120,
      };
    });
    return road;
  }

  function segmentAt(road, s) {
    const st = road.stations;
    let i = 0;
    while (i < st.length - 2 && st[i + 1] <= s) i++;
    return i;
  }

  function roadHeading(road, s) {
    const i = segmentAt(road, s);
    const [x0, y0] = road.points[i];
    const [x1, y1] = road.points[i + 1];
    return Math.atan2(y1 - y0, x1 - x0);
  }

  function project(road, x, y) { // site xy -> road frame (station, offset)
    let best = { dist: Infinity, s: 0, d: 0 };
    for (let i = 0; i + 1 < road.points.length; i++) {
      const [x0, y0] = road.points[i];
      const [x1, y1] = road.points[i + 1];
      const dx = x1 - x0;
      const dy = y1 - y0;
      const len = Math.hypot(dx, dy);
      const t = Math.max(0, Math.min(1, ((x - x0) * dx + (y - y0) * dy) / (len * len)));
      const px = x0 + t * dx;
      const py = y0 + t * dy;
      const dist = Math.hypot(x - px, y - py);
      if (dist < best.dist) {
        best = { dist, s: road.stations[i] + t * len, d: (dx * (y - y0) - dy * (x - x0)) / len };
      }
    }
    return best;
  }

  function limitAt(road, s) {
    const limits = road.limits;
    for (const limit of limits) {
      if (limit.start_station_m <= s && s < limit.end_station_m) return limit.speed_limit_mph * MPS_PER_MPH;
    }
    const edge = s < limits[0].start_station_m ? limits[0] : limits[limits.length - 1];
    return edge.speed_limit_mph * MPS_PER_MPH;
  }

  function speedBand(road, speed, s) {
    const limit = limitAt(road, s);
    const overMph = (speed - limit) / MPS_PER_MPH;
    if (speed < 0.5 * limit) return "slow";
    if (overMph <= 0) return "ok";
    if (overMph < road.marginMph) return "near";
    if (overMph < road.criticalMph) return "over";
    return "critical";
  }

  function applySite(site) {
    const road = buildRoad(site);
    state.road = road;
    $("site-name").textContent = site.name;
    const names = site.road_names.length ? site.road_names.join(", ") : site.site_id;
    $("site-detail").textContent = `${names} ${site.road_direction === "unknown" ? "" : site.road_direction} \u00b7 site ${site.site_id} \u00b7 taper at ${Math.round(road.taperStart)} m`;
    const zoneMph = Math.round(road.zoneLimitMps / MPS_PER_MPH);
    $("zone-limit").textContent = String(zoneMph);
    const m = road.marginMph;
    const c = road.criticalMph;
    const legend = [
      ["slow", `slow (< ${Math.round(zoneMph / 2)} mph)`],
      ["ok", `at or under the limit (\u2264 ${zoneMph})`],
      ["near", `up to ${m} over (${zoneMph}\u2013${zoneMph + m})`],
      ["over", `speeding (${zoneMph + m}\u2013${zoneMph + c})`],
      ["critical", `${c}+ over (> ${zoneMph + c})`],
    ];
    const list = $("legend");
    list.replaceChildren(...legend.map(([band, text]) => {
      const item = document.createElement("li");
      const swatch = document.createElement("span");
      swatch.className = "swatch";
      swatch.style.background = SPEED_COLORS[band];
      item.append(swatch, text);
      return item;
    }));
    const note = document.createElement("li");
    note.className = "muted";
    note.textContent = "speed against the limit where the vehicle is; outlined: coasting (no fresh measurement)";
    list.append(note);
    resetView();
    draw();
  }

  // --- data -----------------------------------------------------------------------------

  function onTracks(data) {
    const road = state.road;
    if (!road) return;
    const previous = state.batch;
    if (previous && data.stamp < previous.stamp) state.trails.clear(); // a new run
    state.batch = data;
    state.batchAt = performance.now() / 1000;
    state.stampOffsetS = data.stamp >= 1e9 ? 0 : data.received_at - data.stamp;
    const seen = new Set();
    for (const track of data.tracks) {
      seen.add(track.track_id);
      let trail = state.trails.get(track.track_id);
      if (!trail) state.trails.set(track.track_id, (trail = []));
      trail.push({ s: track.station_m, d: track.offset_m, t: data.stamp });
      while (trail.length && trail[0].t < data.stamp - TRAIL_S) trail.shift();
    }
    for (const [id, trail] of state.trails) {
      if (!seen.has(id) && (!trail.length || trail[trail.length - 1].t < data.stamp - 2.0)) state.trails.delete(id);
    }
    live.batches += 1;
    live.stamp = data.stamp;
    live.tracks = data.tracks.map((t) => ({
      track_id: t.track_id, x_m: t.x_m, y_m: t.y_m, station_m: t.station_m,
      offset_m: t.offset_m, speed_mps: t.speed_mps,
    }));
    document.body.dataset.trackCount = String(data.tracks.length);
    if (live.connection === "stale") setConnection("live");
    $("track-count").textContent = String(data.tracks.length);
    const fastest = data.tracks.reduce((top, t) => Math.max(top, t.speed_mps), 0);
    $("fastest").textContent = data.tracks.length ? `${Math.round(fastest / MPS_PER_MPH)} mph` : "--";
    updateTable();
    requestDraw();
  }

  function onAlert(alert, fresh) {
    if (state.alertIds.has(alert.alert_id)) return;
    state.alertIds.add(alert.alert_id);
    if (fresh) state.alerts.unshift(alert);
    else state.alerts.push(alert);
    while (state.alerts.length > MAX_ALERTS) state.alertIds.delete(state.alerts.pop().alert_id);
    live.alerts = state.alerts.map((a) => a.alert_id);
    document.body.dataset.alertCount = String(state.alerts.length);
    renderAlerts(fresh ? alert.alert_id : null);
  }

  async function loadAlerts() {
    for (let attempt = 0; attempt < 5; attempt++) {
      try {
        const page = await getJson("/v1/alerts?limit=100&order=newest");
        for (const alert of page.alerts) onAlert(alert, false);
        return;
      } catch (error) {
        if (error instanceof AuthError) return;
        await sleep(2000);
      }
    }
  }

  // The sensors' self-calibration: each sensor's newest SensorCalibration message, as its
  // detector published it; ageS: how long ago the gateway received it.
  function onCalibration(message, ageS) {
    if (state.road && message.site !== state.road.site.site_id) return; // another site's
    const receivedAt = performance.now() / 1000 - ageS;
    const known = state.calibration.get(message.source_id);
    if (known && known.message && known.receivedAt > receivedAt) return; // we have a newer one
    state.calibration.set(message.source_id, { kind: message.sensor_kind, message, receivedAt });
    renderCalibration();
  }

  async function loadCalibration(site) {
    for (let attempt = 0; attempt < 5; attempt++) {
      try {
        const answer = await getJson(`/v1/calibration?site=${encodeURIComponent(site.site_id)}&changes=0`);
        for (const sensor of answer.sensors) {
          if (sensor.calibration) onCalibration(sensor.calibration, sensor.age_s);
          else if (!state.calibration.has(sensor.sensor_id)) {
            state.calibration.set(sensor.sensor_id, { kind: sensor.sensor_kind, message: null, receivedAt: null });
          }
        }
        renderCalibration();
        return;
      } catch (error) {
        if (error instanceof AuthError) return;
        await sleep(2000);
      }
    }
  }

  function signed(value, digits, unit) {
    const text = value.toFixed(digits);
    return `${value > 0 && Number(text) !== 0 ? "+" : ""}${text}${unit}`;
  }

  function stdText(std, digits, unit) {
    return std === null || std === undefined ? "not observed" : `\u00b1 ${std.toFixed(digits)}${unit}`;
  }

  function duration(seconds) {
    if (seconds < 120) return `${Math.round(seconds)} s`;
    if (seconds < 7200) return `${Math.round(seconds / 60)} min`;
    return `${Math.round(seconds / 3600)} h`;
  }

  function renderCalibration() {
    const now = performance.now() / 1000;
    const view = {};
    let bumped = 0;
    const order = state.road ? state.road.sensors.map((sensor) => sensor.id) : [];
    const rank = (id) => (order.includes(id) ? order.indexOf(id) : order.length);
    const entries = [...state.calibration.entries()].sort((a, b) => rank(a[0]) - rank(b[0]));
    const rows = entries.map(([sensorId, entry]) => {
      const row = document.createElement("tr");
      row.dataset.sensorId = sensorId;
      const message = entry.message;
      if (!message) {
        row.className = "silent";
        row.append(element("td", "", sensorId), element("td", "", entry.kind),
          element("td", "state", "not heard"), element("td", "", "--"), element("td", "", "--"),
          element("td", "", "--"), element("td", "", "--"));
        row.title = "Nothing received from this sensor's detector";
        return row;
      }
      const stale = now - entry.receivedAt > CALIBRATION_STALE_S;
      const c = message.correction;
      const clockMs = message.clock_offset_s * 1000;
      row.className = `${message.state}${stale ? " stale" : ""}`;
      if (message.state === "bumped") bumped += 1;
      const yaw = element("td", "", signed(c.yaw_deg, 2, "\u00b0"));
      yaw.title = stdText(c.yaw_std_deg, 2, "\u00b0");
      const pitch = element("td", "", signed(c.pitch_deg, 2, "\u00b0"));
      pitch.title = stdText(c.pitch_std_deg, 2, "\u00b0");
      const clock = element("td", "", signed(clockMs, 0, " ms"));
      const clockStd = message.clock_offset_std_s;
      clock.title = clockStd === null ? "not observed" : `\u00b1 ${(clockStd * 1000).toFixed(0)} ms`;
      row.append(element("td", "", sensorId), element("td", "", message.sensor_kind),
        element("td", "state", message.state), yaw, pitch, clock,
        element("td", "", duration(Math.max(0, message.stamp - message.state_since_s))));
      const heard = `received ${duration(now - entry.receivedAt)} ago`;
      row.title = message.detail ? `${message.detail} (${heard})` : heard;
      view[sensorId] = {
        kind: message.sensor_kind, state: message.state, yaw_deg: c.yaw_deg,
        pitch_deg: c.pitch_deg, clock_offset_ms: clockMs, stale,
      };
      return row;
    });
    $("calibration-rows").replaceChildren(...rows);
    $("no-calibration").hidden = rows.length > 0;
    live.calibration = view;
    document.body.dataset.calibrationBumped = String(bumped);
    $("calibration-summary").textContent = bumped
      ? `${bumped} sensor${bumped === 1 ? "" : "s"} moved: pose being learned again`
      : "";
  }

  // --- the alert list and the table ------------------------------------------------------

  function alertTime(alert) {
    const offset = alert.stamp >= 1e9 ? 0 : state.stampOffsetS;
    if (offset === null) return `t = ${alert.stamp.toFixed(1)} s`;
    return new Date((alert.stamp + offset) * 1000).toLocaleTimeString([], { hour12: false });
  }

  function element(tag, className, text) {
    const node = document.createElement(tag);
    if (className) node.className = className;
    if (text !== undefined) node.textContent = text;
    return node;
  }

  function renderAlerts(freshId) {
    const items = state.alerts.map((alert) => {
      const item = element("li", `${alert.severity} ${alert.phase}`);
      if (alert.alert_id === freshId) item.classList.add("fresh");
      item.dataset.alertId = alert.alert_id;
      const top = element("div", "alert-top");
      top.append(element("span", `badge ${alert.severity}`, alert.severity),
        element("span", "alert-type", ALERT_NAMES[alert.alert_type] || alert.alert_type),
        element("span", "phase", alert.phase === "start" ? "" : alert.phase),
        element("span", "alert-time", alertTime(alert)));
      const meta = element("div", "alert-meta");
      meta.append(element("span", "", alert.track_id === null ? "site" : `track #${alert.track_id}`));
      if (alert.speed_mps !== null) meta.append(element("span", "", `${Math.round(alert.speed_mps / MPS_PER_MPH)} mph`));
      meta.append(element("span", "", `station ${Math.round(alert.station_m)} m`));
      item.append(top, meta, element("div", "alert-text", alert.description));
      item.addEventListener("click", () => focusOn(alert.station_m, alert.track_id));
      return item;
    });
    $("alerts").replaceChildren(...items);
    $("no-alerts").hidden = items.length > 0;
    $("alert-summary").textContent = items.length ? `${items.length} event${items.length === 1 ? "" : "s"}, newest first` : "";
  }

  function laneName(road, index) {
    if (index < 0) return "between";
    if (road.lanes.length === 2) return index === 0 ? "right" : "left";
    return `lane ${index}`;
  }

  function updateTable() {
    const road = state.road;
    const tracks = (state.batch ? state.batch.tracks : [])
      .filter((t) => t.station_m < road.taperStart + 250)
      .sort((a, b) => Math.abs(a.station_m - road.taperStart) - Math.abs(b.station_m - road.taperStart))
      .slice(0, TABLE_ROWS);
    $("track-rows").replaceChildren(...tracks.map((t) => {
      const row = document.createElement("tr");
      const id = element("td");
      const chip = element("span", "chip");
      chip.style.background = SPEED_COLORS[speedBand(road, t.speed_mps, t.station_m)];
      id.append(chip, `#${t.track_id}`);
      const toTaper = road.taperStart - t.station_m;
      row.append(id, element("td", "", t.object_class), element("td", "", laneName(road, t.lane_index)),
        element("td", "", `${Math.round(t.station_m)} m`),
        element("td", "", toTaper >= 0 ? `${Math.round(toTaper)} m` : "in taper or past"),
        element("td", "", `${Math.round(t.speed_mps / MPS_PER_MPH)} mph`));
      return row;
    }));
  }

  // --- drawing ----------------------------------------------------------------------------

  function fitCanvas(canvas) {
    const ratio = window.devicePixelRatio || 1;
    const width = Math.max(1, canvas.clientWidth);
    const height = Math.max(1, canvas.clientHeight);
    if (canvas.width !== Math.round(width * ratio) || canvas.height !== Math.round(height * ratio)) {
      canvas.width = Math.round(width * ratio);
      canvas.height = Math.round(height * ratio);
    }
    const ctx = canvas.getContext("2d");
    ctx.setTransform(ratio, 0, 0, ratio, 0, 0);
    return { ctx, width, height };
  }

  function requestDraw() {
    if (state.drawQueued) return;
    state.drawQueued = true;
    requestAnimationFrame(() => {
      state.drawQueued = false;
      draw();
    });
  }

  function draw() {
    if (!state.road) return;
    drawOverview();
    drawPlan();
  }

  function resetView() {
    const road = state.road;
    const canvas = $("plan");
    const start = Math.max(0, road.taperStart - 100);
    const end = Math.min(road.length, road.taperStart + 80);
    state.view = {
      s: (start + end) / 2, d: (road.leftEdge + road.rightEdge) / 2,
      scale: Math.max(1, canvas.clientWidth) / (end - start),
    };
  }

  function focusOn(station, trackId) {
    state.view.s = station;
    state.view.scale = Math.max(state.view.scale, 5);
    if (trackId !== null && trackId !== undefined) state.highlight = { trackId, until: performance.now() + 6000 };
    requestDraw();
  }

  function vehicleSize(track) {
    const [length, width] = SIZES[track.object_class] || SIZES.unknown;
    return [track.length_m || length, track.width_m || width];
  }

  function drawZonePolygons(ctx, road, toScreen) {
    // The closed lane: the taper closes it from its outer edge, then buffer, work area and
    // the termination taper that hands it back.
    const { closedOuter: outer, closedInner: inner, areas } = road;
    const fill = (corners, color) => {
      ctx.beginPath();
      corners.forEach(([s, d], i) => {
        const [x, y] = toScreen(s, d);
        if (i === 0) ctx.moveTo(x, y); else ctx.lineTo(x, y);
      });
      ctx.closePath();
      ctx.fillStyle = color;
      ctx.fill();
    };
    if (areas.transition) {
      const { start, end } = areas.transition;
      fill([[start, outer], [end, outer], [end, inner]], "rgba(242,140,40,0.55)");
    }
    if (areas.buffer) {
      const { start, end } = areas.buffer;
      fill([[start, outer], [end, outer], [end, inner], [start, inner]], "rgba(255,179,92,0.30)");
    }
    if (areas.activity) {
      const { start, end } = areas.activity;
      fill([[start, outer], [end, outer], [end, inner], [start, inner]], "rgba(242,109,33,0.70)");
    }
    if (areas.termination) {
      const { start, end } = areas.termination;
      fill([[start, outer], [start, inner], [end, outer]], "rgba(201,162,39,0.45)");
    }
  }

  function coneLine(road) { // [s, d] of the channelizing devices along the closure
    const { closedOuter: outer, closedInner: inner, areas } = road;
    const cones = [];
    if (areas.transition) {
      const { start, end } = areas.transition;
      const n = Math.max(2, Math.round((end - start) / 12));
      for (let k = 0; k <= n; k++) cones.push([start + (end - start) * k / n, outer + (inner - outer) * k / n]);
      const stop = areas.activity ? areas.activity.end : end;
      for (let s = end + 12; s < stop; s += 12) cones.push([s, inner]);
    }
    if (areas.termination) {
      const { start, end } = areas.termination;
      const n = Math.max(2, Math.round((end - start) / 8));
      for (let k = 0; k <= n; k++) cones.push([start + (end - start) * k / n, inner + (outer - inner) * k / n]);
    }
    return cones;
  }

  function drawOverview() {
    const road = state.road;
    const { ctx, width, height } = fitCanvas($("overview"));
    const margin = 16;
    const xScale = (width - 2 * margin) / road.length;
    const laneH = 15; // px per lane: the lanes widened so that the whole site fits
    const latScale = laneH / road.closed.width_m;
    const centerY = height / 2 + 10;
    const midD = (road.leftEdge + road.rightEdge) / 2;
    const toScreen = (s, d) => [margin + s * xScale, centerY - (d - midD) * latScale];
    ctx.clearRect(0, 0, width, height);

    // the areas: a band above the road, with names
    ctx.font = "11px DejaVu Sans, sans-serif";
    ctx.textBaseline = "alphabetic";
    const [, top] = toScreen(0, road.leftEdge + 1.5);
    for (const [kind, style] of Object.entries(AREA_STYLE)) {
      const area = road.areas[kind];
      if (!area) continue;
      const [x0] = toScreen(area.start, 0);
      const [x1] = toScreen(area.end, 0);
      ctx.fillStyle = style.color;
      ctx.globalAlpha = 0.85;
      ctx.fillRect(x0, top - 14, Math.max(1, x1 - x0 - 1), 5);
      ctx.globalAlpha = 1;
      const label = style.label;
      if (ctx.measureText(label).width < x1 - x0 + 30) {
        ctx.fillStyle = "#d9e1ec";
        ctx.fillText(label, x0, top - 19);
      }
    }
    // the road
    const [, yLeft] = toScreen(0, road.leftEdge);
    const [, yRight] = toScreen(0, road.rightEdge);
    ctx.fillStyle = "#3b4048";
    ctx.fillRect(margin, yLeft - 3, road.length * xScale, yRight - yLeft + 6);
    drawZonePolygons(ctx, road, toScreen);
    ctx.strokeStyle = "#e8e8e8";
    ctx.lineWidth = 1;
    ctx.setLineDash([4, 5]);
    for (const lane of road.lanes.slice(0, -1)) {
      const [, y] = toScreen(0, lane.center_offset_m + lane.width_m / 2);
      ctx.beginPath();
      ctx.moveTo(margin, y);
      ctx.lineTo(margin + road.length * xScale, y);
      ctx.stroke();
    }
    ctx.setLineDash([]);
    // speed-limit signs where the limit changes
    ctx.font = "bold 10px DejaVu Sans, sans-serif";
    for (const limit of road.limits) {
      const [x] = toScreen(limit.start_station_m, 0);
      const [, y] = toScreen(0, road.rightEdge - 2.5);
      ctx.fillStyle = "#fff";
      ctx.fillRect(x, y, 22, 15);
      ctx.strokeStyle = "#000";
      ctx.strokeRect(x + 1.5, y + 1.5, 19, 12);
      ctx.fillStyle = "#000";
      ctx.textAlign = "center";
      ctx.fillText(String(Math.round(limit.speed_limit_mph)), x + 11, y + 11.5);
      ctx.textAlign = "left";
    }
    // station ticks
    ctx.fillStyle = "#95a1b2";
    ctx.strokeStyle = "#6b7686";
    ctx.font = "10.5px DejaVu Sans, sans-serif";
    const tickEvery = road.length > 1500 ? 100 : 50;
    const labelEvery = tickEvery * (xScale * tickEvery * 2 < 60 ? 4 : 2);
    for (let s = 0; s <= road.length; s += tickEvery) {
      const [x] = toScreen(s, 0);
      ctx.beginPath();
      ctx.moveTo(x, height - 14);
      ctx.lineTo(x, height - (s % labelEvery === 0 ? 20 : 17));
      ctx.stroke();
      if (s % labelEvery === 0) {
        ctx.textAlign = "center";
        ctx.fillText(`${s} m`, Math.min(Math.max(x, 18), width - 18), height - 3);
        ctx.textAlign = "left";
      }
    }
    // the mast(s)
    drawMasts(ctx, road, toScreen, false);
    // the plan view's window
    const view = state.view;
    const planWidth = $("plan").clientWidth;
    const half = planWidth / view.scale / 2;
    const [vx0] = toScreen(Math.max(0, view.s - half), 0);
    const [vx1] = toScreen(Math.min(road.length, view.s + half), 0);
    ctx.strokeStyle = "#ffffffb0";
    ctx.lineWidth = 1.5;
    ctx.strokeRect(vx0, yLeft - 9, Math.max(2, vx1 - vx0), yRight - yLeft + 18);
    // vehicles: arrows in the direction of travel, coloured by speed
    const batch = state.batch;
    if (!batch) return;
    for (const track of batch.tracks) {
      const [x, y] = toScreen(track.station_m, track.offset_m);
      ctx.fillStyle = SPEED_COLORS[speedBand(road, track.speed_mps, track.station_m)];
      ctx.beginPath();
      ctx.moveTo(x + 5, y);
      ctx.lineTo(x - 4, y - 4.5);
      ctx.lineTo(x - 4, y + 4.5);
      ctx.closePath();
      ctx.fill();
      ctx.strokeStyle = "#000a";
      ctx.lineWidth = 1;
      ctx.stroke();
    }
  }

  function drawMasts(ctx, road, toScreen, detailed) {
    const groups = new Map(); // sensors on one mast, within 2 m of one another
    for (const sensor of road.sensors) {
      const key = `${Math.round(sensor.s / 2)}:${Math.round(sensor.d / 2)}`;
      if (!groups.has(key)) groups.set(key, []);
      groups.get(key).push(sensor);
    }
    for (const sensors of groups.values()) {
      const [x, y] = toScreen(sensors[0].s, sensors[0].d);
      ctx.fillStyle = "#e8edf3";
      ctx.strokeStyle = "#11151b";
      ctx.lineWidth = 1.5;
      ctx.beginPath();
      ctx.rect(x - 4.5, y - 4.5, 9, 9);
      ctx.fill();
      ctx.stroke();
      ctx.font = "11px DejaVu Sans, sans-serif";
      ctx.fillStyle = "#e8edf3";
      const label = detailed ? `mast: ${sensors.map((s) => s.kind).join(", ")}` : "mast";
      ctx.fillText(label, x + 8, y + 14);
    }
  }

  function drawPlan() {
    const road = state.road;
    const canvas = $("plan");
    const { ctx, width, height } = fitCanvas(canvas);
    const view = state.view;
    const toScreen = (s, d) => [width / 2 + (s - view.s) * view.scale, height / 2 - (d - view.d) * view.scale];
    const sMin = view.s - width / 2 / view.scale;
    const sMax = view.s + width / 2 / view.scale;
    $("plan-range").textContent = `stations ${Math.round(Math.max(0, sMin))}\u2013${Math.round(Math.min(road.length, sMax))} m, true scale`;
    ctx.fillStyle = "#1f2a1f"; // verge
    ctx.fillRect(0, 0, width, height);

    // sensor coverage, faint
    for (const sensor of road.sensors) {
      const [x, y] = toScreen(sensor.s, sensor.d);
      const r = sensor.range * view.scale;
      ctx.beginPath();
      if (sensor.fov >= 2 * Math.PI - 1e-6) {
        ctx.setLineDash([6, 6]);
        ctx.strokeStyle = "rgba(160,200,255,0.25)";
        ctx.arc(x, y, r, 0, 2 * Math.PI);
        ctx.stroke();
        ctx.setLineDash([]);
      } else {
        ctx.moveTo(x, y);
        ctx.arc(x, y, r, -sensor.yaw - sensor.fov / 2, -sensor.yaw + sensor.fov / 2);
        ctx.closePath();
        ctx.fillStyle = sensor.kind === "camera" ? "rgba(160,200,255,0.045)" : "rgba(200,160,255,0.04)";
        ctx.fill();
      }
    }

    // the road: shoulders, lanes, closure, markings
    const clipStart = Math.max(0, sMin);
    const clipEnd = Math.min(road.length, sMax);
    const [xa, yLeft] = toScreen(clipStart, road.leftEdge);
    const [xb, yRight] = toScreen(clipEnd, road.rightEdge);
    const [, yLeftShoulder] = toScreen(0, road.leftEdge + 1.2);
    const [, yRightShoulder] = toScreen(0, road.rightEdge - 3.0);
    ctx.fillStyle = "#33373d";
    ctx.fillRect(xa, yLeftShoulder, xb - xa, yRightShoulder - yLeftShoulder);
    ctx.fillStyle = "#41464e";
    ctx.fillRect(xa, yLeft, xb - xa, yRight - yLeft);
    drawZonePolygons(ctx, road, toScreen);
    if (road.areas.buffer) { // hatching: nobody belongs there
      const { start, end } = road.areas.buffer;
      const [x0, y0] = toScreen(start, road.closedOuter);
      const [x1, y1] = toScreen(end, road.closedInner);
      ctx.save();
      ctx.beginPath();
      ctx.rect(Math.min(x0, x1), Math.min(y0, y1), Math.abs(x1 - x0), Math.abs(y1 - y0));
      ctx.clip();
      ctx.strokeStyle = "rgba(255,255,255,0.45)";
      ctx.lineWidth = 2;
      const step = 14;
      for (let x = Math.min(x0, x1) - Math.abs(y1 - y0); x < Math.max(x0, x1); x += step) {
        ctx.beginPath();
        ctx.moveTo(x, Math.max(y0, y1));
        ctx.lineTo(x + Math.abs(y1 - y0), Math.min(y0, y1));
        ctx.stroke();
      }
      ctx.restore();
    }
    if (road.areas.activity) {
      const { start, end } = road.areas.activity;
      const [x0, y0] = toScreen(Math.max(start, sMin), road.closedOuter);
      const [x1, y1] = toScreen(Math.min(end, sMax), road.closedInner);
      if (x1 - x0 > 90) {
        ctx.fillStyle = "#1a1206";
        ctx.font = `bold ${Math.min(16, Math.max(10, Math.abs(y1 - y0) * 0.55))}px DejaVu Sans, sans-serif`;
        ctx.textAlign = "center";
        ctx.textBaseline = "middle";
        ctx.fillText("WORK AREA", (x0 + x1) / 2, (y0 + y1) / 2);
        ctx.textAlign = "left";
        ctx.textBaseline = "alphabetic";
      }
    }
    // edge lines (left yellow, right white, as on a US divided highway) and lane lines
    ctx.lineWidth = Math.max(1, 0.15 * view.scale);
    ctx.strokeStyle = "#f2c94c";
    ctx.beginPath();
    ctx.moveTo(xa, yLeft);
    ctx.lineTo(xb, yLeft);
    ctx.stroke();
    ctx.strokeStyle = "#f4f4f4";
    ctx.beginPath();
    ctx.moveTo(xa, yRight);
    ctx.lineTo(xb, yRight);
    ctx.stroke();
    ctx.setLineDash([3 * view.scale, 9 * view.scale]); // 10 ft lines, 30 ft gaps
    for (const lane of road.lanes.slice(0, -1)) {
      const [, y] = toScreen(0, lane.center_offset_m + lane.width_m / 2);
      ctx.beginPath();
      ctx.moveTo(xa - ((xa - toScreen(0, 0)[0]) % (12 * view.scale)), y);
      ctx.lineTo(xb, y);
      ctx.stroke();
    }
    ctx.setLineDash([]);
    // cones
    const coneR = Math.max(2, 0.35 * view.scale);
    for (const [s, d] of coneLine(road)) {
      if (s < sMin - 5 || s > sMax + 5) continue;
      const [x, y] = toScreen(s, d);
      ctx.beginPath();
      ctx.arc(x, y, coneR, 0, 2 * Math.PI);
      ctx.fillStyle = "#ff7a1a";
      ctx.fill();
      ctx.strokeStyle = "#fff";
      ctx.lineWidth = 1;
      ctx.stroke();
    }
    // the areas' boundaries and names, along the top
    ctx.font = "12px DejaVu Sans, sans-serif";
    for (const [kind, style] of Object.entries(AREA_STYLE)) {
      const area = road.areas[kind];
      if (!area || area.end < sMin || area.start > sMax) continue;
      const [x0] = toScreen(area.start, 0);
      const [x1] = toScreen(area.end, 0);
      const left = Math.max(0, x0);
      const right = Math.min(width, x1);
      ctx.fillStyle = style.color;
      ctx.fillRect(left, 8, Math.max(1, right - left - 2), 4);
      ctx.strokeStyle = "rgba(255,255,255,0.12)";
      ctx.beginPath();
      ctx.moveTo(x0, 12);
      ctx.lineTo(x0, height - 22);
      ctx.stroke();
      const label = `${style.label} ${Math.round(area.start)}\u2013${Math.round(area.end)} m`;
      if (right - left > ctx.measureText(label).width + 8) {
        ctx.fillStyle = "#d9e1ec";
        ctx.fillText(label, left + 4, 26);
      }
    }
    // station ticks along the bottom
    const tickEvery = [1, 2, 5, 10, 20, 25, 50, 100, 200, 500].find((t) => t * view.scale >= 40) || 1000;
    ctx.font = "11px DejaVu Sans, sans-serif";
    ctx.strokeStyle = "#7d8897";
    ctx.fillStyle = "#aab4c3";
    ctx.lineWidth = 1;
    for (let s = Math.ceil(Math.max(0, sMin) / tickEvery) * tickEvery; s <= Math.min(road.length, sMax); s += tickEvery) {
      const [x] = toScreen(s, 0);
      const major = s % (tickEvery * 2) === 0;
      ctx.beginPath();
      ctx.moveTo(x, height - 18);
      ctx.lineTo(x, height - (major ? 26 : 22));
      ctx.stroke();
      if (major) {
        ctx.textAlign = "center";
        ctx.fillText(`${s} m`, Math.min(Math.max(x, 22), width - 22), height - 5);
        ctx.textAlign = "left";
      }
    }
    drawMasts(ctx, road, toScreen, true);
    drawVehicles(ctx, road, toScreen, sMin, sMax);
  }

  function drawVehicles(ctx, road, toScreen, sMin, sMax) {
    const batch = state.batch;
    const scale = state.view.scale;
    // trails first, under every vehicle
    for (const trail of state.trails.values()) {
      if (trail.length < 2) continue;
      ctx.lineWidth = Math.max(1.5, 0.35 * scale);
      for (let i = 1; i < trail.length; i++) {
        const [x0, y0] = toScreen(trail[i - 1].s, trail[i - 1].d);
        const [x1, y1] = toScreen(trail[i].s, trail[i].d);
        ctx.strokeStyle = `rgba(200,225,255,${(0.45 * i / trail.length).toFixed(3)})`;
        ctx.beginPath();
        ctx.moveTo(x0, y0);
        ctx.lineTo(x1, y1);
        ctx.stroke();
      }
    }
    if (!batch) return;
    const highlight = state.highlight && state.highlight.until > performance.now() ? state.highlight.trackId : null;
    ctx.font = `${scale >= 4 ? 12 : 10}px DejaVu Sans, sans-serif`;
    for (const track of batch.tracks) {
      if (track.station_m < sMin - 20 || track.station_m > sMax + 20) continue;
      const [length, width] = vehicleSize(track);
      const [x, y] = toScreen(track.station_m, track.offset_m);
      const angle = track.heading_rad - roadHeading(road, track.station_m);
      const color = SPEED_COLORS[speedBand(road, track.speed_mps, track.station_m)];
      const w = Math.max(length * scale, 6);
      const h = Math.max(width * scale, 3.5);
      ctx.save();
      ctx.translate(x, y);
      ctx.rotate(-angle); // screen y points down, the road frame's d up
      ctx.beginPath();
      ctx.rect(-w / 2, -h / 2, w, h);
      if (track.status === "confirmed") {
        ctx.fillStyle = color;
        ctx.fill();
        ctx.strokeStyle = "#0b0e12";
        ctx.lineWidth = 1;
        ctx.stroke();
        ctx.fillStyle = "rgba(10,14,20,0.55)"; // the windscreen: which end is the front
        ctx.fillRect(w / 2 - Math.min(w * 0.3, 1.6 * scale), -h / 2 + 1, Math.max(1.5, 0.5 * scale), h - 2);
      } else {
        ctx.setLineDash(track.status === "coasting" ? [4, 3] : []);
        ctx.strokeStyle = color;
        ctx.lineWidth = 2;
        ctx.stroke();
        ctx.setLineDash([]);
      }
      ctx.restore();
      if (track.track_id === highlight) {
        ctx.strokeStyle = "#fff";
        ctx.lineWidth = 2;
        ctx.beginPath();
        ctx.arc(x, y, Math.max(w, h) / 2 + 8, 0, 2 * Math.PI);
        ctx.stroke();
      }
      const label = scale >= 3 ? `#${track.track_id} ${Math.round(track.speed_mps / MPS_PER_MPH)} mph` : `#${track.track_id}`;
      ctx.fillStyle = "#f4f7fb";
      ctx.strokeStyle = "rgba(0,0,0,0.75)";
      ctx.lineWidth = 3;
      ctx.strokeText(label, x - w / 2, y - h / 2 - 5);
      ctx.fillText(label, x - w / 2, y - h / 2 - 5);
    }
  }

  // --- interaction ----------------------------------------------------------------------

  function setupInteraction() {
    const plan = $("plan");
    const clampScale = (scale) => {
      const road = state.road;
      const min = road ? plan.clientWidth / road.length : 0.2;
      return Math.min(40, Math.max(min, scale));
    };
    plan.addEventListener("wheel", (event) => {
      if (!state.view) return;
      event.preventDefault();
      const rect = plan.getBoundingClientRect();
      const view = state.view;
      const sAt = view.s + (event.clientX - rect.left - rect.width / 2) / view.scale;
      const scale = clampScale(view.scale * Math.exp(-event.deltaY * 0.0015));
      view.s = sAt - (event.clientX - rect.left - rect.width / 2) / scale;
      view.scale = scale;
      requestDraw();
    }, { passive: false });
    let drag = null;
    plan.addEventListener("pointerdown", (event) => {
      if (!state.view) return;
      drag = { x: event.clientX, y: event.clientY, s: state.view.s, d: state.view.d };
      plan.setPointerCapture(event.pointerId);
      plan.classList.add("dragging");
    });
    plan.addEventListener("pointermove", (event) => {
      if (!drag) return;
      state.view.s = drag.s - (event.clientX - drag.x) / state.view.scale;
      state.view.d = drag.d + (event.clientY - drag.y) / state.view.scale;
      requestDraw();
    });
    const end = () => {
      drag = null;
      plan.classList.remove("dragging");
    };
    plan.addEventListener("pointerup", end);
    plan.addEventListener("pointercancel", end);
    const zoom = (factor) => {
      if (!state.view) return;
      state.view.scale = clampScale(state.view.scale * factor);
      requestDraw();
    };
    $("zoom-in").addEventListener("click", () => zoom(1.5));
    $("zoom-out").addEventListener("click", () => zoom(1 / 1.5));
    $("zoom-reset").addEventListener("click", () => {
      if (!state.road) return;
      resetView();
      requestDraw();
    });
    const overview = $("overview");
    overview.addEventListener("click", (event) => {
      const road = state.road;
      if (!road) return;
      const rect = overview.getBoundingClientRect();
      const s = (event.clientX - rect.left - 16) / (rect.width - 32) * road.length;
      focusOn(Math.max(0, Math.min(road.length, s)), null);
    });
    new ResizeObserver(() => requestDraw()).observe(plan);
    $("key-form").addEventListener("submit", () => {
      const key = $("key-input").value.trim();
      if (key) sessionStorage.setItem(KEY_STORE, key);
      location.reload();
    });
  }

  // --- start ----------------------------------------------------------------------------

  async function start() {
    setupInteraction();
    setInterval(tick, 250);
    let site = null;
    while (site === null) {
      try {
        site = await getJson("/v1/site");
      } catch (error) {
        if (error instanceof AuthError) return;
        setConnection("offline");
        await sleep(retryMs);
      }
    }
    applySite(site);
    follow(); // the stream first, so that no alert falls between the list and the stream
    loadAlerts();
    loadCalibration(site);
  }

  start();
})();
