// vascsim dashboard: charts from the page's JSON, the session timeline, the live view.
"use strict";

const pageData = JSON.parse(document.getElementById("page-data").textContent || "{}");
const PLOT_CONFIG = { displaylogo: false, responsive: true };
const COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"];

function plotDiv(parent, id) {
  const div = document.createElement("div");
  div.id = id;
  parent.appendChild(div);
  return div;
}

// -- participant progress: one learning curve per benchmarked metric -------------------
function drawCurves() {
  const host = document.getElementById("curves");
  if (!host) return;
  if (!pageData.curves || !pageData.curves.length) {
    host.textContent = "No scored sessions yet.";
    return;
  }
  pageData.curves.forEach((curve, k) => {
    const div = plotDiv(host, "curve-" + k);
    const passed = curve.passed;  // this task's sessions, in the curve's order
    const traces = [{
      x: curve.trial, y: curve.value, mode: "lines+markers", name: curve.metric,
      marker: { color: passed.map((p) => (p === false ? "#b42318" : "#1a7f37")), size: 8 },
      line: { color: "#57606a" },
      text: curve.phase, hovertemplate: "trial %{x} (%{text}): %{y:.4g}<extra></extra>",
    }];
    const shapes = curve.benchmark === null ? [] : [{
      type: "line", xref: "paper", x0: 0, x1: 1, y0: curve.benchmark, y1: curve.benchmark,
      line: { color: "#0969da", dash: "dash" },
    }];
    Plotly.newPlot(div, traces, {
      title: { text: curve.metric + " (" + curve.better + " is better; dashed: benchmark)", font: { size: 13 } },
      xaxis: { title: { text: "trial" }, dtick: 1 }, yaxis: { title: { text: curve.unit } },
      shapes: shapes, height: 260, margin: { t: 40, b: 40, l: 60, r: 10 }, showlegend: false,
    }, PLOT_CONFIG);
  });
}

// -- session review: signals, video, shared timeline -----------------------------------
function cursorShape(t) {
  return { type: "line", xref: "x", yref: "paper", x0: t, x1: t, y0: 0, y1: 1, line: { color: "#d62728", width: 2 } };
}

// a filter by kind above the event list: every kind present, or one
function eventFilter(list, events) {
  const kinds = [...new Map(events.map((e) => [e.kind, e.name])).entries()];
  if (kinds.length < 2) return;
  const select = document.createElement("select");
  select.id = "event-kind";
  select.setAttribute("aria-label", "show events of kind");
  select.add(new Option("all events", ""));
  kinds.forEach(([kind, name]) => select.add(new Option(name, kind)));
  select.addEventListener("change", () => {
    list.querySelectorAll("li").forEach((item) => {
      item.hidden = select.value !== "" && item.dataset.kind !== select.value;
    });
  });
  list.parentNode.insertBefore(select, list);
}

// events drawn on the session's plots, and their colours (the list below the plots names them all)
const MARKED = {
  pierce: "#1a8a4a", exit: "#2a6fb0", pull_through: "#777777",
  overstress: "#c0392b", edge_overstress: "#c0392b", force_clamped: "#c0392b",
};

const WARNINGS = new Set(["overstress", "edge_overstress", "force_clamped"]);

function markerShapes(events) {
  // the needle's passage as full-height dotted lines; warnings as short red ticks along the top, so
  // a run of them does not hide the curve
  // a run of warnings (an episode: its first time to "until") is a red bar along the top
  return events.filter((e) => MARKED[e.kind]).map((e) => (e.until > e.time ? {
    type: "rect", xref: "x", yref: "paper", x0: e.time, x1: e.until, y0: 0.9, y1: 1,
    fillcolor: MARKED[e.kind], opacity: 0.6, line: { width: 0 },
  } : {
    type: "line", xref: "x", yref: "paper", x0: e.time, x1: e.time,
    y0: WARNINGS.has(e.kind) ? 0.9 : 0, y1: 1,
    line: { color: MARKED[e.kind], width: WARNINGS.has(e.kind) ? 1.5 : 1, dash: WARNINGS.has(e.kind) ? "solid" : "dot" },
  }));
}

function bandShape(band) {
  return {
    type: "rect", xref: "paper", x0: 0, x1: 1, yref: "y", y0: band.low, y1: band.high,
    fillcolor: "rgba(42, 111, 176, 0.13)", line: { width: 0 }, layer: "below",
  };
}

async function drawSession() {
  const host = document.getElementById("signals");
  const video = document.getElementById("replay");
  const list = document.getElementById("events");
  const safetyList = document.getElementById("safety-events");
  if (!host) return;
  const response = await fetch("/api/sessions/" + encodeURIComponent(pageData.uid) + "/signals");
  if (!response.ok) {
    host.textContent = "Signals unavailable: " + ((await response.json()).error || {}).message;
    return;
  }
  const data = await response.json();
  host.innerHTML = "";
  const plots = [];
  const markers = markerShapes(data.events || []);
  const bands = pageData.signal_bands || {};
  Object.entries(data.signals).forEach(([name, signal], k) => {
    const div = plotDiv(host, "plot-" + name);
    div.classList.add("signal-plot");
    div.fixedShapes = markers.concat(bands[name] ? [bandShape(bands[name])] : []);
    Plotly.newPlot(div, [{
      x: signal.time, y: signal.values, mode: "lines", name: name, line: { color: COLOURS[k % COLOURS.length] },
    }], {
      yaxis: { title: { text: signal.label } }, xaxis: { title: { text: "time (s)" }, range: [0, data.duration_s] },
      shapes: [cursorShape(0)].concat(div.fixedShapes), height: 220, margin: { t: 10, b: 40, l: 70, r: 10 },
      showlegend: false, hovermode: "x",
      annotations: bands[name] ? [{
        xref: "paper", x: 0.01, xanchor: "left", yref: "y", y: bands[name].high, yanchor: "bottom",
        text: bands[name].label, showarrow: false, font: { size: 10, color: "#2a6fb0" },
      }] : [],
    }, PLOT_CONFIG);
    // a click anywhere on the plot area seeks to that time (a drag still zooms). Plotly covers the page
    // while a button is down, so the press is read on the plot and the release on the window.
    div.addEventListener("pointerdown", (event) => {
      const area = div.querySelector(".nsewdrag");
      if (!area) return;
      const rect = area.getBoundingClientRect();
      if (event.clientX < rect.left || event.clientX > rect.right) return;
      const pressedAt = event.clientX;
      window.addEventListener("pointerup", (release) => {
        if (Math.abs(release.clientX - pressedAt) > 4) return;
        const t = div._fullLayout.xaxis.p2d(pressedAt - rect.left);
        seek(Math.min(Math.max(t, 0), data.duration_s));
      }, { once: true });
    }, true);
    plots.push(div);
  });
  (data.events || []).forEach((event) => {
    const item = document.createElement("li");
    item.dataset.kind = event.kind;
    const button = document.createElement("button");
    button.type = "button";
    button.className = "event";
    button.dataset.time = event.time;
    const detail = event.detail ? " (" + event.detail + ")" : "";
    const count = event.count > 1 ? " ×" + event.count : "";
    const when = event.until > event.time ? event.time.toFixed(2) + "-" + event.until.toFixed(2) : event.time.toFixed(2);
    button.textContent = when + " s: " + event.name + detail + count;
    if (event.explanation) button.title = event.explanation;
    button.addEventListener("click", () => seek(event.time));
    item.appendChild(button);
    if (event.explanation) {
      const note = document.createElement("span");
      note.className = "event-note";
      note.textContent = " (" + event.explanation + ")";
      item.appendChild(note);
    }
    (event.safety && safetyList ? safetyList : list).appendChild(item);
  });
  if (safetyList && !safetyList.children.length) {
    const none = document.createElement("li");
    none.className = "none";
    none.textContent = "None in this session: no overstress, no force limited, no device fault.";
    safetyList.appendChild(none);
  }
  eventFilter(list, (data.events || []).filter((e) => !e.safety));

  function moveCursor(t) {
    host.dataset.cursor = t.toFixed(3);
    plots.forEach((div) => Plotly.relayout(div, { shapes: [cursorShape(t)].concat(div.fixedShapes) }));
  }
  function seek(t) {
    if (video) video.currentTime = t; else moveCursor(t);
  }
  if (video) {
    let last = -1;
    const follow = () => {
      if (Math.abs(video.currentTime - last) > 0.02) {
        last = video.currentTime;
        moveCursor(last);
      }
    };
    video.addEventListener("timeupdate", follow);
    video.addEventListener("seeked", follow);
  }
  host.dataset.ready = "1";
}

// -- construct validity: box plots and ROC curves --------------------------------------
function drawValidity() {
  const boxes = document.getElementById("boxes");
  if (!boxes) return;
  const groups = pageData.groups;
  Object.entries(pageData.boxes).forEach(([metric, values], k) => {
    const div = plotDiv(boxes, "box-" + k);
    Plotly.newPlot(div, groups.map((group, g) => ({
      y: values[group], name: group, type: "box", boxpoints: "all", jitter: 0.4, pointpos: 0,
      marker: { color: COLOURS[g] },
    })), {
      title: { text: metric, font: { size: 12 } }, height: 260, margin: { t: 35, b: 30, l: 60, r: 10 },
      yaxis: { title: { text: (pageData.box_axes || {})[metric] || "", font: { size: 11 } } },
      showlegend: false,
    }, PLOT_CONFIG);
  });
  const roc = document.getElementById("roc");
  const traces = pageData.roc.map((curve, k) => ({
    x: curve.fpr, y: curve.tpr, mode: "lines", name: curve.metric, line: { color: COLOURS[k % COLOURS.length] },
  }));
  traces.push({ x: [0, 1], y: [0, 1], mode: "lines", name: "chance", line: { color: "#999", dash: "dot" } });
  Plotly.newPlot(roc, traces, {
    xaxis: { title: { text: "false positive rate" }, range: [0, 1] },
    yaxis: { title: { text: "true positive rate (" + groups[0] + ")" }, range: [0, 1] },
    height: 420, margin: { t: 10, b: 50, l: 60, r: 10 },
  }, PLOT_CONFIG);
}

// -- live view: server-sent events from the recorder's journals ------------------------
function drawLive() {
  const host = document.getElementById("live-plots");
  if (!host) return;
  const status = document.getElementById("live-status");
  const list = document.getElementById("live-events");
  const names = [["force", "force (mN)"], ["tip_speed", "tip speed (mm/s)"], ["stress", "local stress (kPa)"]];
  const divs = names.map(([name, label], k) => {
    const div = plotDiv(host, "live-" + name);
    Plotly.newPlot(div, [{ x: [], y: [], mode: "lines", line: { color: COLOURS[k] } }], {
      yaxis: { title: { text: label } }, xaxis: { title: { text: "time (s)" } }, height: 200,
      margin: { t: 10, b: 40, l: 70, r: 10 },
    }, PLOT_CONFIG);
    return div;
  });
  let received = 0;
  const source = new EventSource(pageData.source);
  source.addEventListener("hello", () => { status.textContent = "connected"; });
  source.addEventListener("samples", (message) => {
    const data = JSON.parse(message.data);
    received += data.time.length;
    names.forEach(([name], k) => Plotly.extendTraces(divs[k], { x: [data.time], y: [data[name]] }, [0], 3000));
    status.textContent = "receiving: " + received + " samples, t = " + data.time[data.time.length - 1].toFixed(2) + " s";
    host.dataset.samples = received;
  });
  source.addEventListener("event", (message) => {
    const event = JSON.parse(message.data);
    const item = document.createElement("li");
    item.textContent = event.time.toFixed(2) + " s: " + event.kind;
    list.appendChild(item);
  });
  let ended = false;
  source.addEventListener("end", (message) => {
    status.textContent = "ended: " + JSON.parse(message.data).reason;
    ended = true;
    source.close();
  });
  watchScene(() => ended);
}

// the station's 3-D view: the newest frame its window published, fetched again as each one arrives
// (one request at a time, about 10 frames/s; a slow viewer gets fewer frames, the recording nothing less)
function watchScene(ended) {
  const image = document.getElementById("live-scene");
  if (!image || !pageData.scene) {
    if (image) { image.hidden = true; document.getElementById("live-scene-note").textContent = "this station does not send its 3-D view"; }
    return;
  }
  const note = document.getElementById("live-scene-note");
  let frames = 0;
  let asked = 0;
  const next = () => { if (!ended()) { asked = Date.now(); image.src = pageData.scene + "?frame=" + asked; } };
  image.addEventListener("load", () => {
    frames += 1;
    image.dataset.frames = frames;
    note.textContent = "the trainee's 3-D view, as their station's window draws it (" + frames + " frames)";
    setTimeout(next, Math.max(0, 66 - (Date.now() - asked)));  // no faster than the station publishes
  });
  image.addEventListener("error", () => {
    note.textContent = ended() ? "the session has ended" : "no 3-D view from this station yet (no window, or not drawn yet)";
    setTimeout(next, 1000);
  });
  next();
}

// -- a replay rendered on request, with its progress ------------------------------------
function renderReplay() {
  const button = document.getElementById("render-button");
  if (!button) return;
  const bar = document.getElementById("render-progress");
  const said = document.getElementById("render-state");
  const address = button.dataset.address || "/api/sessions/" + encodeURIComponent(pageData.uid) + "/replay";
  async function poll() {
    const answer = await (await fetch(address)).json();
    if (answer.state === "rendering") {
      bar.hidden = false;
      bar.max = answer.frames || 1;
      bar.value = answer.frames_done;
      said.textContent = answer.frames ? "rendering frame " + answer.frames_done + " of " + answer.frames : "preparing...";
      setTimeout(poll, 1000);
    } else if (answer.state === "ready") {
      said.textContent = "done: loading the video";
      window.location.reload();
    } else if (answer.state === "failed") {
      said.textContent = "the render failed: " + answer.error;
      button.disabled = false;
    }
  }
  button.addEventListener("click", async () => {
    button.disabled = true;
    const answer = await fetch(address, { method: "POST", headers: { "X-CSRF-Token": button.dataset.csrf } });
    if (!answer.ok) {
      said.textContent = ((await answer.json()).error || {}).message || "the render could not start";
      button.disabled = false;
      return;
    }
    poll();
  });
  fetch(address).then((r) => r.json()).then((answer) => { if (answer.state === "rendering") { button.disabled = true; poll(); } });
}

document.addEventListener("DOMContentLoaded", () => {
  const page = document.body.dataset.page;
  if (page === "participant") drawCurves();
  if (page === "session") { drawSession(); renderReplay(); }
  if (page === "rate") renderReplay();
  if (page === "validity") drawValidity();
  if (page === "live") drawLive();
});
