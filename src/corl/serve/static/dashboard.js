// The live dashboard of `corl serve`: server-sent events update the page as trials arrive.
"use strict";
const $ = (id) => document.getElementById(id);
const fmt = (x, d = 4) => (x === null || x === undefined) ? "\u2013" : Number(x).toFixed(d);
// J spans decades (the door: 2381 -> 205; the synthetic task: 1e-6): one format down the column, 4 digits,
// the exponent with two digits as Python's "%.3e" writes it (corl report's table).
const fmtJ = (x) => (x === null || x === undefined) ? "\u2013" :
  Number(x).toExponential(3).replace(/e([+-])(\d)$/, "e$10$2");
const rows = new Map();  // trial index -> <tr>

function setText(id, text) { $(id).textContent = text; }

const scene = (c) => (c === null || c === undefined) ? "" : `context [${c.map((v) => +v.toFixed(4)).join(", ")}]`;
let shownRun = null;  // the run whose trials the table shows: a robot in another scene switches it

function showStatus(s) {
  if (s.run !== shownRun) {  // another run (another scene): its own trials, numbered from 0
    shownRun = s.run;
    rows.clear();
    $("trial-rows").replaceChildren();
  }
  const where = s.context === null || s.context === undefined ? "" : ` \u00b7 ${scene(s.context)}`;
  setText("title", `\u00b7 ${s.task} \u00b7 ${s.method} \u00b7 seed ${s.seed} \u00b7 run ${s.run}${where} \u00b7 ${s.store}`);
  const scenes = (s.runs || []).filter((r) => r.context !== null);
  setText("scenes", scenes.length ? "runs by scene: " + scenes.map((r) =>
    `run ${r.run} ${scene(r.context)} (${r.told} told, ${r.status})`).join("; ") : "");
  setText("trials", s.trials);
  setText("failures", s.failures);
  const out = s.pending_trials;  // corl serve --robots K: every trial out, and the robot holding each
  const held = out ? out.map((i, k) => (s.pending_robots[k] === null ? `${i}` : `${i} (${s.pending_robots[k]})`)) : [];
  setText("pending", out ? (out.length ? `${held.join(", ")} of ${s.robots} robots` : "none") :
    (s.pending === null ? "none" : s.pending));
  const told = s.best_observed;
  setText("best-told", told ? fmt(told.return) : "\u2013");
  setText("best-told-detail", told ? `trial ${told.trial}, theta ${JSON.stringify(told.theta.map((v) => +v.toFixed(4)))}` : "");
  setText("best", s.best ? fmt(s.best.return) + (s.best.return_std === null ? "" : ` \u00b1 ${fmt(s.best.return_std)}`) : "\u2013");
  setText("best-theta", s.best ? `theta ${JSON.stringify(s.best.theta.map((v) => +v.toFixed(4)))}` : "");
  setText("step", s.step === null ? "\u2013" : `${s.step}, ${s.round}`);
  const state = $("state");
  state.classList.toggle("done", s.done);
  state.textContent = s.done ? `finished: ${s.stop_reason}` :
    (s.pending === null ? "waiting for the next ask" :
      (out && out.length > 1 ? `trials ${out.join(", ")} are on the robots` : `trial ${s.pending} is on the robot`));
  state.classList.toggle("offline", Boolean(s.broken));
  if (s.broken) state.textContent = `stopped: ${s.broken}; restart corl serve on the same store`;
  document.body.dataset.trials = s.trials;
  document.body.dataset.version = s.version;
  loadTrials();
}

function showRow(t) {
  let tr = rows.get(t.trial);
  if (!tr) {
    tr = document.createElement("tr");
    tr.dataset.trial = t.trial;
    $("trial-rows").prepend(tr);
    rows.set(t.trial, tr);
  }
  const outcome = t.success === null ? "pending" : (t.success ? "success" : "failure");
  tr.className = outcome;
  tr.dataset.outcome = outcome;
  const cells = [t.trial, t.step, t.round, JSON.stringify(t.theta.map((v) => +v.toFixed(4))), outcome,
    fmt(t["return"]), fmtJ(t.J)];
  tr.replaceChildren(...cells.map((c) => { const td = document.createElement("td"); td.textContent = c; return td; }));
}

let loading = false, again = false;
async function loadTrials() {
  if (loading) { again = true; return; }
  loading = true;
  try {
    let since = 0;  // from the first trial not told yet: a pending row gets its outcome
    for (const [i, tr] of rows) if (tr.dataset.outcome !== "pending" && i + 1 > since) since = i + 1;
    const pending = [...rows.values()].filter((tr) => tr.dataset.outcome === "pending").map((tr) => +tr.dataset.trial);
    if (pending.length) since = Math.min(since, ...pending);
    const answer = await (await fetch(`/trials?since=${since}`, {cache: "no-store"})).json();
    if (answer.run === shownRun) answer.trials.forEach(showRow);  // not a run the robot has just left
    document.body.dataset.rows = rows.size;
  } finally {
    loading = false;
    if (again) { again = false; loadTrials(); }
  }
}

function showFigures(f) {
  for (const name of ["trials", "return_map"]) {
    const img = $(`fig-${name}`);
    if (f.figures.includes(name)) { img.src = `/figures/${name}.png?v=${f.version}`; img.hidden = false; }
    else img.hidden = true;
    setText(`note-${name}`, f.notes[name] || "");
  }
  document.body.dataset.figures = f.version;
}

function showVideo(v) {
  $("video-section").hidden = false;
  if (v.available) {
    $("video").src = `/video?v=${v.version}`;
    setText("video-caption", `Left: the demonstration. Right: trial ${v.trial}, rendered in the simulator.`);
  } else setText("video-caption", v.note);
}

function connect() {
  const source = new EventSource("/events");
  source.addEventListener("open", () => { document.body.dataset.connected = "yes"; });
  source.addEventListener("status", (e) => showStatus(JSON.parse(e.data)));
  source.addEventListener("figures", (e) => showFigures(JSON.parse(e.data)));
  source.addEventListener("video", (e) => showVideo(JSON.parse(e.data)));
  source.addEventListener("error", () => {
    document.body.dataset.connected = "no";
    const state = $("state");
    state.classList.add("offline");
    state.textContent = "the server is not reachable; retrying\u2026";
  });
}
connect();
