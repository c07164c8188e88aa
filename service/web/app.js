// The lab's page: every action is a call of the service's REST API (fetch, same origin) with the key the
// user gave, kept in sessionStorage and sent as "Authorization: Bearer <key>". No library, no build step.
"use strict";

const KEY_STORE = "microbearing.apiKey";
// The API's root, relative to this page (/ui/ -> /), so that a proxy's path prefix is kept.
const BASE = new URL("..", window.location.href);
const POLL_MS = 600;

const state = {
  physicsInputs: new Set(["balls", "load_N", "speed_m_s"]),  // replaced by GET /v1/parameters
  sentColumns: {},  // the open calibration's headers as uploaded -> its columns ("load [mN]" -> "load_N")
  calibrations: [],
  report: null,   // the calibration report on show
  plan: null,     // the last proposal of next runs
  objectUrls: [], // blob: URLs of the plots on show, released when replaced
};

const $ = (id) => document.getElementById(id);

/** An element with attributes (a "text" key sets its text) and children (strings or nodes). */
function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs || {})) {
    if (value === undefined || value === null || value === false) continue;
    if (name === "text") node.textContent = value;
    else node.setAttribute(name, value === true ? "" : value);
  }
  for (const child of children.flat()) {
    if (child !== null && child !== undefined) node.append(child);
  }
  return node;
}

/** A number in 4 significant digits (as the tests read it back), or a dash. */
function num(value) {
  if (value === null || value === undefined || Number.isNaN(value)) return "—";
  if (typeof value !== "number") return String(value);
  return Number(value.toPrecision(4)).toString();
}

function percent(value) {
  return value === null || value === undefined ? "—" : `${num(100 * value)} %`;
}

function apiUrl(path) {
  return new URL(String(path).replace(/^\//, ""), BASE);
}

/** An API answer that is not 2xx: its problem (RFC 9457) and status. */
class ApiError extends Error {
  constructor(problem, status) {
    super(problem.detail || problem.title || `HTTP ${status}`);
    this.problem = problem;
    this.status = status;
  }
}

async function api(method, path, options = {}) {
  const headers = new Headers();
  const key = sessionStorage.getItem(KEY_STORE);
  if (key) headers.set("Authorization", `Bearer ${key}`);
  const init = { method, headers };
  if (options.json !== undefined) {
    init.body = JSON.stringify(options.json);
    headers.set("Content-Type", "application/json");
  } else if (options.body !== undefined) {
    init.body = options.body;
    headers.set("Content-Type", options.contentType || "text/csv");
  }
  let response;
  try {
    response = await fetch(apiUrl(path), init);
  } catch (error) {
    throw new ApiError({ title: "The service cannot be reached", detail: String(error) }, 0);
  }
  if (!response.ok) {
    let problem;
    try {
      problem = await response.json();
    } catch {
      problem = { title: response.statusText || "Error", detail: `HTTP ${response.status}` };
    }
    throw new ApiError(problem, response.status);
  }
  return response;
}

/** Show an error in ``box``: the problem's title and detail, and each offending field by name; focus moves
 * there unless ``quiet`` (an error of the page's own start, which must not take the focus from the user). */
function showProblem(box, error, quiet) {
  const problem = error instanceof ApiError ? error.problem
    : { title: "Error in the page", detail: String(error && error.message ? error.message : error) };
  const status = error instanceof ApiError && error.status ? ` (${error.status})` : "";
  box.replaceChildren(
    el("p", {}, el("strong", { text: `${problem.title || "Error"}${status}` })),
    el("p", { text: problem.detail || "" }));
  const fields = Array.isArray(problem.errors) ? problem.errors : [];
  if (fields.length) {
    box.append(el("ul", { class: "fields" }, fields.map((item) => el("li", {},
      el("code", { class: "field", text: item.pointer || item.parameter || item.header || item.field || "request" }),
      `: ${item.detail || item.message || ""}`))));
  }
  if (error instanceof ApiError && error.status === 401) {
    box.append(el("p", { text: "Paste a valid API key at the top of the page." }));
  }
  box.hidden = false;
  if (!quiet) box.focus();
}

function clearProblem(box) {
  box.hidden = true;
  box.replaceChildren();
}

/** The answer of a call that may run as a job (202): the job polled to its end, with progress and cancel. */
async function answerOrJob(response, ui) {
  if (response.status !== 202) return response.json();
  const job = await response.json();
  return followJob(job.id, ui);
}

async function followJob(jobId, ui) {
  const box = $(`${ui}-job`);
  const bar = $(`${ui}-progress`);
  const label = $(`${ui}-state`);
  const cancel = $(`${ui}-cancel`);
  box.hidden = false;
  cancel.disabled = false;
  cancel.onclick = async () => {
    cancel.disabled = true;
    label.textContent = "cancelling…";
    try {
      await api("DELETE", `v1/jobs/${jobId}`);
    } catch (error) {
      label.textContent = `could not cancel: ${error.message}`;
    }
  };
  try {
    for (;;) {
      const job = await (await api("GET", `v1/jobs/${jobId}`)).json();
      bar.value = job.progress;
      label.textContent = `${job.status}, ${Math.round(100 * job.progress)} % done`;
      if (job.status === "succeeded") {
        return await (await api("GET", `v1/jobs/${jobId}/result`)).json();
      }
      if (job.status === "failed") {
        throw new ApiError(job.error || { title: "The job failed", detail: "" }, job.error ? job.error.status : 0);
      }
      if (job.status === "cancelled") {
        throw new ApiError({ title: "Cancelled", detail: "The job was cancelled; nothing was stored." }, 0);
      }
      await new Promise((resolve) => setTimeout(resolve, POLL_MS));
    }
  } finally {
    cancel.disabled = true;
    cancel.onclick = null;
  }
}

/** A PNG of the API shown inline: fetched with the key, shown from a blob: URL. */
function plotFigure(path, alt, caption, wide) {
  const img = el("img", { alt, class: "plot" });
  api("GET", path).then((response) => response.blob()).then((blob) => {
    const url = URL.createObjectURL(blob);
    state.objectUrls.push(url);
    img.src = url;
  }).catch((error) => img.replaceWith(el("p", { class: "problem", text: `The plot could not be loaded: ${error.message}` })));
  return el("figure", { class: wide }, img, el("figcaption", { text: caption }));
}

function releasePlots() {
  state.objectUrls.forEach((url) => URL.revokeObjectURL(url));
  state.objectUrls = [];
}

function table(caption, header, rows) {
  return el("div", { class: "scroll", role: "region", "aria-label": caption, tabindex: "0" },
    el("table", {}, el("caption", { text: caption }),
      el("thead", {}, el("tr", {}, header.map((h) => el("th", { scope: "col", text: h })))),
      el("tbody", {}, rows.map((row) => el("tr", {}, row.map((cell) => el("td", {}, cell)))))));
}

function rawJson(what, document_) {
  return el("details", { class: "raw" }, el("summary", { text: `Raw JSON of ${what}` }),
    el("pre", { tabindex: "0", text: JSON.stringify(document_, null, 2) }));
}

function list(items) {
  return el("ul", {}, items.map((item) => el("li", {}, item)));
}

// ---- the key ------------------------------------------------------------------------------------------

function showKeyStatus() {
  $("key-status").textContent = sessionStorage.getItem(KEY_STORE)
    ? "A key is set for this tab." : "No key set: calls go without one.";
}

// ---- 1. upload ----------------------------------------------------------------------------------------

/** The dialect and units the service reads in the file, before any fit (POST v1/calibrations/csv/intake). */
async function previewFile(file) {
  const query = new URLSearchParams({ separator: $("separator").value, decimal: $("decimal").value });
  const box = $("preview");
  box.replaceChildren(el("p", { text: `Reading ${file.name}…` }));
  try {
    const response = await api("POST", `v1/calibrations/csv/intake?${query}`, { body: await file.arrayBuffer() });
    const reading = await response.json();
    const intake = reading.intake;
    box.replaceChildren(
      el("h3", { text: `How the service reads ${file.name} (nothing is fitted yet)` }),
      el("p", { id: "preview-dialect", text: `${reading.rows} data rows; separator ${intake.separator} (`
        + `${intake.detected.includes("separator") ? "detected" : "stated"}), decimal mark ${intake.decimal} (`
        + `${intake.detected.includes("decimal") ? "detected" : "stated"}), ${intake.encoding}, `
        + `${intake.line_endings} line ends; ignored: ${intake.ignored.join("; ") || "nothing"}.` }),
      table("Each column as written and its name in the data (SI)", ["Column as written", "Read as"],
        Object.entries(intake.columns)),
      intake.conversions.length ? list(intake.conversions) : el("p", { text: "No unit conversion." }),
      el("p", { id: "preview-groups", text: reading.factors.length
        ? `Read as groups (labels): ${reading.factors.join(", ")}.` : "No column is read as groups." }));
  } catch (error) {
    box.replaceChildren(el("h3", { text: `The service cannot read ${file.name} as it is` }));
    const problem = el("div", { class: "problem", role: "alert" });
    box.append(problem);
    showProblem(problem, error);
  }
}

async function upload(event) {
  event.preventDefault();
  const box = $("upload-error");
  clearProblem(box);
  const file = $("csv-file").files[0];
  if (!file) {
    showProblem(box, new ApiError({ title: "No file", detail: "Choose a CSV file first.",
      errors: [{ field: "file", detail: "no file chosen" }] }, 0));
    return;
  }
  const query = new URLSearchParams();
  $("fit-parameters").value.split(",").map((s) => s.trim()).filter(Boolean)
    .forEach((name) => query.append("fit_parameters", name));
  query.set("separator", $("separator").value);
  query.set("decimal", $("decimal").value);
  if ($("folds").value.trim()) query.set("folds", $("folds").value);  // empty: the service's default
  $("upload-start").disabled = true;
  try {
    const response = await api("POST", `v1/calibrations/csv?${query}`, { body: await file.arrayBuffer() });
    const report = await answerOrJob(response, "upload");
    $("upload-state").textContent = "done: the report is below";
    await refreshModels();
    showReport(report);
    $("report-h").scrollIntoView();
  } catch (error) {
    showProblem(box, error);
  } finally {
    $("upload-start").disabled = false;
  }
}

function setupDrop() {
  const drop = $("drop");
  const input = $("csv-file");
  input.addEventListener("change", async () => {
    if (input.files[0]) previewFile(input.files[0]);
  });
  ["separator", "decimal"].forEach((id) => $(id).addEventListener("change", () => {
    if (input.files[0]) previewFile(input.files[0]);
  }));
  ["dragenter", "dragover"].forEach((name) => drop.addEventListener(name, (event) => {
    event.preventDefault();
    drop.classList.add("over");
  }));
  ["dragleave", "drop"].forEach((name) => drop.addEventListener(name, () => drop.classList.remove("over")));
  drop.addEventListener("drop", (event) => {
    event.preventDefault();
    if (event.dataTransfer.files.length) {
      input.files = event.dataTransfer.files;
      input.dispatchEvent(new Event("change"));
    }
  });
}

// ---- 2. the report ------------------------------------------------------------------------------------

const PLOT_TEXT = {
  residuals: ["Residuals log(measured / predicted μ) [1] against every input, before and after the terms were added",
    "Residuals before and after"],
  measured_vs_predicted: ["Measured μ [1] against predicted μ [1], with the line of equality",
    "Measured against predicted μ [1]"],
};

function plotText(name, report) {
  const match = /^effect_(\d+)$/.exec(name);
  if (match) {
    const term = (report.effects || [])[Number(match[1]) - 1] || report.missing_effect || {};
    const driver = (term.drivers || [])[0] || "its driver";
    const text = `Term ${match[1]} (${term.label || term.name || "added term"}): log(μ / μ without the term) [1] `
      + `against ${driver} in the data's unit, with its 95 % band`;
    return [text, text];
  }
  return PLOT_TEXT[name] || [`Plot ${name}`, name];
}

function showReport(report) {
  state.report = report;
  releasePlots();
  $("report-empty").hidden = true;
  const body = $("report-body");
  const effects = report.effects || (report.missing_effect ? [report.missing_effect] : []);
  const before = report.error_before;
  const after = report.error_after;
  const named = report.missing_effect ? report.missing_effect.label || report.missing_effect.name : "nothing";
  const parts = [
    el("p", { class: "model-id" }, "Calibration ", el("code", { id: "report-id", text: report.id }), ` on ${report.n_points} measurements; `
      + "use it as the model ", el("code", { text: report.model_id }), "."),
    el("h3", { text: "What the model missed" }),
    el("p", {}, "The declared model missed: ", el("strong", { id: "report-effect", text: named }),
      effects.length > 1 ? ` (and ${effects.length - 1} more term${effects.length > 2 ? "s" : ""}: `
        + `${effects.slice(1).map((e) => e.label || e.name).join("; ")})` : "",
      effects.length ? "" : " beyond noise: no term beats the declared model held out."),
    effects.length ? list(effects.map((e) => `${e.title}: ${e.formula}`)) : null,
    el("h3", { text: "Error before and after (held out)" }),
    el("p", {}, "Relative RMSE of μ: ", el("strong", { id: "report-error-before", text: num(before.relative_rmse) }),
      " before (the declared model, fitted) → ", el("strong", { id: "report-error-after", text: num(after.relative_rmse) }),
      ` after (${percent(before.relative_rmse)} → ${percent(after.relative_rmse)}); RMSE of μ ${num(before.rmse)} → `
      + `${num(after.rmse)} [1]. Each row is predicted by a model built without it (cross-validation).`),
    el("h3", { text: "How sure" }),
    list([
      ...Object.entries(report.fitted_parameters || {}).map(([name, e]) =>
        `${name} = ${num(e.value)} ± ${num(e.std)} (95 %: ${num(e.value - 1.96 * e.std)} to ${num(e.value + 1.96 * e.std)})`),
      ...effects.flatMap((e) => Object.entries(e.parameters || {}).map(([name, value]) =>
        `${e.label || e.name}: ${name} = ${num(value)} ± ${num((e.parameter_std || {})[name])} `
        + `[${(e.parameter_units || {})[name] || "1"}]`)),
      report.effect_stability ? report.effect_stability.summary : null,
      report.scatter ? report.scatter.summary : null,
      ...(report.groups || []).map((g) => g.summary).filter(Boolean),
    ].filter(Boolean)),
  ];
  if ((report.rivals || []).length) {
    parts.push(el("h4", { text: "Rivals: laws that fit about as well (kept in the intervals)" }),
      list(report.rivals.map((r) => r.statement)));
  }
  // The rivals' statements come again among what the data cannot decide: listed once, under rivals.
  const rivalStatements = new Set((report.rivals || []).map((r) => r.statement));
  const undecided = (report.undecided || []).map((u) => u.statement).filter((s) => !rivalStatements.has(s));
  if (undecided.length) {
    parts.push(el("h4", { text: "What the data cannot decide" }), list(undecided));
  }
  if ((report.confounding || []).length) {
    parts.push(el("h4", { text: "Columns that move together" }), list(report.confounding));
  }
  parts.push(el("h3", { text: "Outliers and warnings" }),
    list([report.outliers ? report.outliers.summary : "no outlier test",
      ...(report.noise ? [report.noise.statement] : []), ...(report.warnings || [])]),
    el("details", {}, el("summary", { text: "Why these terms (the selection in words)" }), el("p", { text: report.decision })));
  if (report.intake) {
    const intake = report.intake;
    parts.push(el("h3", { text: "How the file was read" }),
      el("p", { id: "report-intake", text: `${intake.format}; separator ${intake.separator || "—"}, decimal mark `
        + `${intake.decimal || "—"} (detected: ${intake.detected.join(", ") || "none"}); ${intake.encoding || ""} `
        + `${intake.line_endings ? `${intake.line_endings} line ends` : ""}; ignored: ${intake.ignored.join("; ") || "nothing"}.` }),
      table("Each column as sent and its name in the data (SI)", ["Column as sent", "Read as"],
        Object.entries(intake.columns)),
      intake.conversions.length ? list(intake.conversions) : el("p", { text: "No unit conversion." }));
  }
  parts.push(el("h3", { text: "Plots" }),
    el("div", { class: "plots" }, Object.entries(report.plots || {}).map(([name, path]) => {
      const [alt, caption] = plotText(name, report);
      return plotFigure(path, alt, caption, name === "residuals" ? "wide" : null);
    })),
    rawJson("the report", report));
  body.replaceChildren(...parts.filter(Boolean));
  prefillFromReport(report);
}

// ---- defaults from the open calibration ---------------------------------------------------------------

function domainOf(report) {
  return (report && report.model && report.model.domain) || {};
}

/** Each column's range in the data under the header and in the unit the upload used (the report's
 * domain.as_sent: "load [mN]: 3 .. 30"), else under its name in SI (a report stored before, or a header
 * a line or a CSV row of the forms cannot hold). */
function rangesAsSent(report) {
  const domain = domainOf(report);
  const sent = report.domain && report.domain.as_sent;
  if (!sent) return Object.entries(domain).map(([name, range]) => ({ key: name, column: name, range }));
  return Object.entries(sent).map(([key, c]) => (/[,:"\n]/.test(key) || !(c.column in domain)
    ? { key: c.column, column: c.column, range: domain[c.column] } : { key, column: c.column, range: c.range }))
    .filter((r) => r.range);
}

function prefillFromReport(report) {
  const domain = domainOf(report);
  const conditions = new Set((report.model && report.model.conditions) || []);
  const round = (x) => Number(x.toPrecision(6));
  const mid = (range) => Number(((range[0] + range[1]) / 2).toPrecision(3));
  const ranges = rangesAsSent(report);
  state.sentColumns = Object.fromEntries(ranges.map((r) => [r.key, r.column]));
  if (ranges.length) {
    $("ask-table").value = `${ranges.map((r) => r.key).join(",")}\n`
      + ranges.map((r) => (r.column === "balls" ? Math.round(mid(r.range)) : mid(r.range))).join(",");
    const line = (r) => `${r.key}: ${round(r.range[0])} .. ${round(r.range[1])}`;
    $("next-space").value = ranges.map(line).join("\n");
    $("design-conditions").value = ranges.filter((r) => conditions.has(r.column)).map(line).join("\n");
  }
  if (domain.balls) [$("design-balls-low").value, $("design-balls-high").value] = domain.balls;
  if (domain.load_N) [$("design-load-low").value, $("design-load-high").value] = domain.load_N;
  if (domain.speed_m_s) [$("design-speed-low").value, $("design-speed-high").value] = domain.speed_m_s;
  document.querySelectorAll(".model-select").forEach((select) => {
    if ([...select.options].some((o) => o.value === report.model_id)) select.value = report.model_id;
  });
}

// ---- 3. ask -------------------------------------------------------------------------------------------

function parseTable(text, what) {
  const lines = text.split(/\r\n|\n/).map((l) => l.trim()).filter(Boolean);
  if (lines.length < 2) throw new ApiError({ title: "Nothing to ask", detail: `${what}: a header and at least one row`,
    errors: [{ field: what, detail: "needs a header line and at least one row" }] }, 0);
  const header = lines[0].split(",").map((s) => s.trim());
  const columns = Object.fromEntries(header.map((h) => [h, []]));
  lines.slice(1).forEach((line, i) => {
    const cells = line.split(",").map((s) => s.trim());
    if (cells.length !== header.length) {
      throw new ApiError({ title: "A row does not match the header", detail: `row ${i + 1} has ${cells.length} cells`,
        errors: [{ field: `${what}, row ${i + 1}`, detail: `${cells.length} cells for ${header.length} columns` }] }, 0);
    }
    cells.forEach((cell, j) => columns[header[j]].push(cell !== "" && !Number.isNaN(Number(cell)) ? Number(cell) : cell));
  });
  return { header, columns, count: lines.length - 1 };
}

async function ask(event) {
  event.preventDefault();
  const box = $("ask-error");
  clearProblem(box);
  try {
    const { header, columns, count } = parseTable($("ask-table").value, "points");
    const model = $("ask-model").value;
    const points = {};
    const conditions = {};
    // a physics input by its name or by the upload's header for it ("load [mN]"): the service reads both
    const isInput = (name) => state.physicsInputs.has(name) || state.physicsInputs.has(state.sentColumns[name]);
    header.forEach((name) => ((isInput(name) ? points : conditions)[name] = columns[name]));
    const body = { points, model, outputs: ["mu"] };
    if (Object.keys(conditions).length) body.conditions = conditions;
    const answer = await (await api("POST", "v1/friction/batch", { json: body })).json();
    const rows = [...Array(count).keys()].map((i) => [
      ...header.map((name) => String(columns[name][i])), num(answer.mu[i]),
      answer.mu_lower ? `${num(answer.mu_lower[i])} to ${num(answer.mu_upper[i])}` : "— (physics: no interval)",
      answer.in_domain ? (answer.in_domain[i] ? "inside the data" : "outside the data: an extrapolation") : "—"]);
    $("ask-result").replaceChildren(
      table(`μ of ${model} at ${count} point${count > 1 ? "s" : ""}`, [...header, "μ [1]", "95 % interval of a measurement [1]",
        "Domain"], rows),
      (answer.domain_warnings || []).length ? list(answer.domain_warnings) : null,
      rawJson("the answer", answer));
  } catch (error) {
    showProblem(box, error);
  }
}

// ---- 4. next runs -------------------------------------------------------------------------------------

/** Lines ``name: low .. high [log]`` or ``name: v1, v2`` (or ``name: value`` with ``single``) as an object. */
function parseRanges(text, what, single) {
  const out = {};
  text.split(/\r\n|\n/).map((l) => l.trim()).filter(Boolean).forEach((line, i) => {
    const match = /^([^:]+):\s*(.+)$/.exec(line);
    const bad = (detail) => new ApiError({ title: "A line cannot be read", detail: `${what}, line ${i + 1}: ${detail}`,
      errors: [{ field: `${what}, line ${i + 1}`, detail }] }, 0);
    if (!match) throw bad("write name: low .. high, or name: v1, v2");
    const name = match[1].trim();
    const rest = match[2].trim();
    const range = /^(\S+)\s*\.\.\s*(\S+)(\s+log)?$/.exec(rest);
    if (range) {
      const [low, high] = [Number(range[1]), Number(range[2])];
      if (Number.isNaN(low) || Number.isNaN(high)) throw bad(`${name}: the ends must be numbers`);
      out[name] = single ? [low, high] : { low, high, spacing: range[3] ? "log" : "linear" };
    } else {
      const values = rest.split(",").map((s) => s.trim());
      if (values.some((v) => v === "" || Number.isNaN(Number(v)))) {
        if (single && values.length === 1) out[name] = values[0];  // a factor's group label
        else throw bad(`${name}: write numbers, low .. high or v1, v2`);
      } else {
        if (single && values.length > 1) throw bad(`${name}: give one value, or a range low .. high`);
        // a set of allowed values is {"values": [...]} in every route; [low, high] is a range
        out[name] = single ? Number(values[0]) : { values: values.map(Number) };
      }
    }
  });
  return out;
}

function calibrationIdOf(modelId) {
  return modelId.replace(/^calibrated:/, "");
}

async function planNext(event) {
  event.preventDefault();
  const box = $("next-error");
  clearProblem(box);
  try {
    const model = $("next-model").value;
    if (!model) {
      throw new ApiError({ title: "No calibration", detail: "Upload measurements or open a calibration first.",
        errors: [{ field: "calibration", detail: "none chosen" }] }, 0);
    }
    const body = { runs: Number($("next-runs").value), goal: $("next-goal").value,
      space: parseRanges($("next-space").value, "space", false) };
    if (body.goal === "predict") body.envelope = body.space;
    const response = await api("POST", `v1/calibrations/${calibrationIdOf(model)}/next-experiments`, { json: body });
    showPlan(await answerOrJob(response, "next"));
  } catch (error) {
    showProblem(box, error);
  }
}

/** The proposal's runs as a CSV the upload reads as it is once mu_measured is filled in. */
function planCsv(plan) {
  const inputs = [...new Set(plan.runs.flatMap((r) => Object.keys(r.inputs)))];
  const conditions = [...new Set(plan.runs.flatMap((r) => Object.keys(r.conditions)))];
  const header = ["balls", "load_N", "speed_m_s", ...inputs, ...conditions, "mu_measured"];
  const lines = plan.runs.map((r) => [r.balls, r.load_N, r.speed_m_s, ...inputs.map((n) => r.inputs[n]),
    ...conditions.map((n) => r.conditions[n]), ""].map((v) => (v === undefined ? "" : String(v))).join(","));
  return { header, text: `${header.join(",")}\n${lines.join("\n")}\n` };
}

function showPlan(plan) {
  state.plan = plan;
  const { header, text } = planCsv(plan);
  const link = el("a", { id: "next-download", class: "button", download: "next-runs.csv",
    href: URL.createObjectURL(new Blob([text], { type: "text/csv" })) }, "Download the runs as CSV");
  const rivals = plan.rivals || [];
  $("next-result").replaceChildren(
    el("p", {}, `${plan.runs.length} runs (${plan.support_points} distinct settings) for the goal ${plan.goal}; `
      + "their efficiency against the best design over the candidates is proven at least ",
      el("strong", { id: "next-efficiency", text: num(plan.efficiency_lower_bound) }), " [1]."),
    rivals.length ? list(rivals.map((r) => `${r.label}: expected χ² separation ${num(r.expected_chi2_separation)} `
      + "(about 9 or more tells it apart)")) : null,
    list(plan.parameters.map((p) => `${p.name}: standard deviation ${num(p.std_now)} now → ${num(p.std_after)} after `
      + `[${p.unit}]`)),
    (plan.warnings || []).length ? el("div", {}, el("h3", { text: "Warnings" }), list(plan.warnings)) : null,
    plan.plot_url ? el("div", { class: "plots" }, plotFigure(plan.plot_url,
      `The proposed runs over the data taken, on ${plan.plot.axes.join(" and ")}, with the models' μ [1]`,
      `Runs over the data on ${plan.plot.axes.join(" and ")} (in their units)`)) : null,
    table("The proposed runs", [...header.slice(0, -1), "μ predicted [1]", "95 % interval [1]", "Domain"],
      plan.runs.map((r) => [String(r.balls), num(r.load_N), num(r.speed_m_s),
        ...header.slice(3, -1).map((n) => num(n in r.inputs ? r.inputs[n] : r.conditions[n])), num(r.mu),
        r.mu_lower === undefined || r.mu_lower === null ? "—" : `${num(r.mu_lower)} to ${num(r.mu_upper)}`,
        r.in_domain === false ? "outside the data" : "inside"])),
    el("p", {}, link, " Fill in mu_measured for each run (the other columns are in SI, as the upload reads them) "
      + "and upload the file in step 1, alone or appended to earlier rows with the same column names."),
    rawJson("the proposal", plan));
}

// ---- 5. design ----------------------------------------------------------------------------------------

function numberOf(id, what) {
  const raw = $(id).value.trim();
  const value = Number(raw);
  if (raw === "" || Number.isNaN(value)) {
    throw new ApiError({ title: "A number is missing", detail: `${what} must be a number`,
      errors: [{ field: what, detail: "must be a number" }] }, 0);
  }
  return value;
}

async function design(event) {
  event.preventDefault();
  const box = $("design-error");
  clearProblem(box);
  try {
    const model = $("design-model").value;
    const speed = [numberOf("design-speed-low", "speed_m_s low"), numberOf("design-speed-high", "speed_m_s high")];
    const body = {
      model,
      objective: $("design-objective").value,
      bounds: { balls: [numberOf("design-balls-low", "bounds.balls low"), numberOf("design-balls-high", "bounds.balls high")],
        groove_angle_deg: [numberOf("design-angle-low", "bounds.groove_angle_deg low"),
          numberOf("design-angle-high", "bounds.groove_angle_deg high")],
        load_N: [numberOf("design-load-low", "bounds.load_N low"), numberOf("design-load-high", "bounds.load_N high")] },
      speed_m_s: speed[0] === speed[1] ? speed[0] : speed,
      starts: numberOf("design-starts", "starts"),
      time_limit_s: numberOf("design-time", "time_limit_s"),
    };
    const tolerance = $("design-tolerance").value.trim();
    if (tolerance !== "" && Number(tolerance) > 0) body.tolerances = { groove_angle_deg: Number(tolerance) };
    const pressure = $("design-pressure").value.trim();
    if (pressure !== "") body.constraints = { max_contact_pressure_Pa: Number(pressure) };
    const conditions = parseRanges($("design-conditions").value, "conditions", true);
    if (Object.keys(conditions).length && model !== "physics") body.conditions = conditions;
    const response = await api("POST", "v1/optimizations", { json: body });
    showDesign(await answerOrJob(response, "design"));
  } catch (error) {
    showProblem(box, error);
  }
}

function showDesign(result) {
  const d = result.design;
  const proof = result.proof;
  const worst = result.worst_case;
  const objective = result.objective || "mu";
  const parts = [
    el("h3", { text: "The design" }),
    el("p", { id: "design-summary" }, el("strong", { id: "design-balls", text: String(d.balls) }), " balls, groove angle ",
      el("strong", { id: "design-angle", text: num(d.groove_angle_deg) }), " deg, load ",
      el("strong", { id: "design-load", text: num(d.load_N) }), ` N (${result.model}, method ${result.method}).`),
    el("p", {}, `μ at the design ${num(result.mu)} [1]`, result.mu_upper !== null && result.mu_upper !== undefined
      ? `; 95 % interval of a measurement ${num(result.mu_lower)} to ${num(result.mu_upper)} [1]` : "",
    result.in_domain === false ? "; outside the calibration data (an extrapolation)." : "."),
  ];
  if (worst) {
    const conditions = Object.entries(worst.conditions || {}).map(([n, v]) => `${n} = ${num(v)}`).join(", ");
    parts.push(el("h3", { text: "Worst case over the envelope" }),
      el("p", {}, `Worst ${objective}: `, el("strong", { id: "design-worst", text: num(worst[objective]) }),
        ` [1] at ${num(worst.speed_m_s)} m/s, groove angle made ${num(worst.groove_angle_deg)} deg`
        + `${conditions ? `, ${conditions}` : ""}.`));
  }
  if (proof) {
    parts.push(el("h3", { text: "Proof" }),
      el("p", {}, "Proven: ", el("strong", { id: "design-proven", text: proof.proven ? "yes" : "no" }),
        ` (${proof.method}; lower bound ${num(proof.lower_bound)}, upper bound ${num(proof.upper_bound)}, relative gap `
        + `${num(proof.relative_gap)}, target ${num(proof.gap_target)}).`),
      el("details", {}, el("summary", { text: "The argument in words" }), el("p", { text: proof.statement })));
    parts.push(el("details", {}, el("summary", { text: "The certificate in full" }),
      el("p", { class: "certificate", text: result.certificate })));
  } else {
    parts.push(el("h3", { text: "Certificate" }), el("p", { class: "certificate", text: result.certificate }));
  }
  if (result.price_of_robustness) {
    const p = result.price_of_robustness;
    parts.push(el("p", { text: `Price of robustness: the nominal optimum (${p.nominal.design.balls} balls, `
      + `${num(p.nominal.design.groove_angle_deg)} deg, ${num(p.nominal.design.load_N)} N) has worst case `
      + `${num(p.nominal.worst_case)}${p.nominal.limits_hold_over_envelope ? "" : " but breaks a limit somewhere in the envelope"}; `
      + `the robust one ${num(p.robust.worst_case)}.` }));
  }
  if ((result.domain_warnings || []).length) parts.push(list(result.domain_warnings));
  parts.push(table("Bounds and limits at the design", ["Name", "Value", "Limit", "Active", "Met"],
    result.constraints.map((c) => [c.name, num(c.value), `${c.sense} ${num(c.limit)}`, c.active ? "yes" : "no",
      c.satisfied ? "yes" : "no"])), rawJson("the design", result));
  $("design-result").replaceChildren(...parts);
}

// ---- 6. my models -------------------------------------------------------------------------------------

function fillModelSelects() {
  document.querySelectorAll(".model-select").forEach((select) => {
    const chosen = select.value;
    const options = select.dataset.physics ? [el("option", { value: "physics", text: "physics (the declared model)" })] : [];
    state.calibrations.forEach((c) => options.push(el("option", { value: c.model_id, text: `${c.name} (${c.id.slice(0, 8)})` })));
    select.replaceChildren(...options);
    if ([...select.options].some((o) => o.value === chosen)) select.value = chosen;
  });
}

async function openCalibration(id) {
  const box = $("models-error");
  clearProblem(box);
  try {
    showReport(await (await api("GET", `v1/calibrations/${id}`)).json());
    $("report-h").scrollIntoView();
  } catch (error) {
    showProblem(box, error);
  }
}

async function deleteModel(kind, id, name) {
  if (!window.confirm(`Delete the ${kind} ${name}? It is gone for every request that names it.`)) return;
  const box = $("models-error");
  clearProblem(box);
  try {
    await api("DELETE", `v1/${kind === "calibration" ? "calibrations" : "surrogates"}/${id}`);
    if ($("surrogate-view").dataset.id === id) {
      $("surrogate-view").replaceChildren();
      delete $("surrogate-view").dataset.id;
    }
    if (state.report && state.report.id === id) {
      state.report = null;
      releasePlots();
      $("report-body").replaceChildren();
      $("report-empty").hidden = false;
    }
    await refreshModels();
  } catch (error) {
    showProblem(box, error);
  }
}

async function openSurrogate(id) {
  const box = $("models-error");
  clearProblem(box);
  try {
    const s = await (await api("GET", `v1/surrogates/${id}`)).json();
    const median = s.metrics ? s.metrics.median_relative_error : null;
    $("surrogate-view").dataset.id = s.id;
    $("surrogate-view").replaceChildren(el("h3", { text: `Surrogate ${s.id}` }),
      el("p", { text: `${s.model} over ${Object.keys(s.space).join(", ")}; ${s.n_train} training runs; median relative `
        + `error held out ${percent(median)}; use it as ${s.model_id}.` }), rawJson("the surrogate", s));
  } catch (error) {
    showProblem(box, error);
  }
}

async function refreshModels(options) {
  const box = $("models-error");
  clearProblem(box);
  try {
    const [calibrations, surrogates] = await Promise.all([
      api("GET", "v1/calibrations?limit=100").then((r) => r.json()),
      api("GET", "v1/surrogates?limit=100").then((r) => r.json())]);
    state.calibrations = calibrations.calibrations;
    fillModelSelects();
    $("calibration-list").replaceChildren(state.calibrations.length ? table("Stored calibrations, newest first",
      ["Name", "Stored (UTC)", "Error before → after", "Actions"], state.calibrations.map((c) => [c.name, c.created_at,
        `${num(c.error_before.relative_rmse)} → ${num(c.error_after.relative_rmse)}`,
        el("span", { class: "actions" },
          el("button", { type: "button", class: "open", "data-id": c.id, "aria-label": `Open calibration ${c.name} (${c.id})` }, "Open"),
          el("button", { type: "button", class: "delete", "data-id": c.id, "aria-label": `Delete calibration ${c.name} (${c.id})` }, "Delete"))]))
      : el("p", { text: "No stored calibration." }));
    $("calibration-list").querySelectorAll("button.open").forEach((b) => b.addEventListener("click", () => openCalibration(b.dataset.id)));
    $("calibration-list").querySelectorAll("button.delete").forEach((b) => b.addEventListener("click",
      () => deleteModel("calibration", b.dataset.id, b.dataset.id)));
    const stored = surrogates.surrogates;
    $("surrogate-list").replaceChildren(stored.length ? table("Stored surrogates, newest first",
      ["Model", "Inputs", "Stored (UTC)", "Actions"], stored.map((s) => [s.model, Object.keys(s.space).join(", "), s.created_at,
        el("span", { class: "actions" },
          el("button", { type: "button", class: "open", "data-id": s.id, "aria-label": `Open surrogate ${s.id}` }, "Open"),
          el("button", { type: "button", class: "delete", "data-id": s.id, "aria-label": `Delete surrogate ${s.id}` }, "Delete"))]))
      : el("p", { text: "No stored surrogate." }));
    $("surrogate-list").querySelectorAll("button.open").forEach((b) => b.addEventListener("click", () => openSurrogate(b.dataset.id)));
    $("surrogate-list").querySelectorAll("button.delete").forEach((b) => b.addEventListener("click",
      () => deleteModel("surrogate", b.dataset.id, b.dataset.id)));
  } catch (error) {
    showProblem(box, error, options && options.quiet);
    if (error instanceof ApiError && error.status === 401) {
      $("key-status").textContent = "The service needs an API key: paste yours above.";
    }
  }
}

async function loadParameters() {
  try {
    const answer = await (await api("GET", "v1/parameters")).json();
    state.physicsInputs = new Set(answer.parameters.map((p) => p.name));
  } catch {
    // The three required inputs stay known; an error shows where the page calls the API next.
  }
}

function start() {
  showKeyStatus();
  $("key-form").addEventListener("submit", (event) => {
    event.preventDefault();
    const key = $("api-key").value.trim();
    if (key) sessionStorage.setItem(KEY_STORE, key);
    else sessionStorage.removeItem(KEY_STORE);
    $("api-key").value = "";
    showKeyStatus();
    loadParameters();
    refreshModels();
  });
  $("key-forget").addEventListener("click", () => {
    sessionStorage.removeItem(KEY_STORE);
    showKeyStatus();
  });
  setupDrop();
  $("upload-form").addEventListener("submit", upload);
  $("ask-form").addEventListener("submit", ask);
  $("next-form").addEventListener("submit", planNext);
  $("design-form").addEventListener("submit", design);
  $("models-refresh").addEventListener("click", refreshModels);
  fillModelSelects();
  loadParameters();
  refreshModels({ quiet: true });
}

document.addEventListener("DOMContentLoaded", start);
