// mvem explorer: the single-page app of `mvem serve` (plain JS, canvas; no library, no build step).
// Every number comes from the server's JSON API (docs/serve.md), which shares its code with the CLI.
"use strict";
(() => {
  const INPUTS = ["n_e", "u_delta", "u_egr", "u_vgt"];
  // signals of the steady-state table: name, description
  const SIGNALS = [
    ["p_im", "intake manifold pressure"], ["p_em", "exhaust manifold pressure"],
    ["W_c", "compressor mass flow"], ["W_egr", "EGR mass flow"], ["W_t", "turbine mass flow"],
    ["x_egr", "EGR fraction"], ["lambda_O", "oxygen/fuel ratio"], ["M_e", "engine torque"],
    ["n_t", "turbo speed"], ["T_em", "exhaust manifold temperature"], ["T_im", "intake manifold temperature"],
    ["X_Oim", "O2 fraction, intake"], ["X_Oem", "O2 fraction, exhaust"], ["Pi_c", "compressor pressure ratio"],
    ["eta_c", "compressor efficiency"], ["eta_tm", "turbine efficiency"], ["BSR", "blade speed ratio"],
    ["u_egr_actual", "EGR valve position"], ["u_vgt_actual", "VGT position"],
  ];
  const $ = (s, r = document) => r.querySelector(s);
  const $$ = (s, r = document) => Array.from(r.querySelectorAll(s));
  const app = { units: {}, steady: null, step: null, map: null, cycle: null, seq: 0, shown: 0, inflight: false, again: false, urlPending: new Set() };
  // hook for the drive-cycle panel: modes come from the server (/api/models "modes"); a label per mode
  const MODE_LABELS = { open: "open loop", closed: "closed loop" };
  window.mvem = app;

  // ---------------------------------------------------------------------------------------------
  // helpers

  function fmt(v) {
    if (v === null || v === undefined) return "–";
    if (typeof v !== "number") return String(v);
    if (!Number.isFinite(v)) return String(v);
    if (v === 0) return "0";
    const a = Math.abs(v);
    return (a >= 1e-3 && a < 1e7) ? v.toPrecision(6) : v.toExponential(5);
  }
  const unit = (n) => app.units[n] ?? "";
  // a table cell holding `text` as text (not markup: names and values from the server or a file)
  function cell(cls, text) {
    const td = document.createElement("td");
    if (cls) td.className = cls;
    td.textContent = text;
    return td;
  }

  // the server's JSON answer; a failure is an Error with its `kind`: "network" (no answer:
  // the server is gone), or "http" with the `status` of the answer
  async function api(path, body) {
    const opts = body === undefined ? {} : { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body) };
    let r;
    try {
      r = await fetch(path, opts);
    } catch (e) {
      const err = new Error(`server unreachable (${e.message})`);
      err.kind = "network";
      throw err;
    }
    // (an answer that is not JSON, from something else than mvem serve: a proxy's page, another
    // server on the port, a crash's text, is named so, with the start of its text, instead of
    // failing later as "Cannot read properties of null")
    const text = await r.text();
    let j = null;
    try { j = JSON.parse(text); } catch (_) { j = null; }
    const head = () => text.trim().replace(/\s+/g, " ").slice(0, 120);
    if (!r.ok) {
      const err = new Error((j && j.error) || `HTTP ${r.status}${head() ? `: ${head()}` : ""}`);
      err.kind = "http";
      err.status = r.status;
      throw err;
    }
    if (j === null || typeof j !== "object") {
      const err = new Error(`the server's answer to ${path.split("?")[0]} is not the JSON of mvem serve (${r.headers.get("content-type") || "no content type"}${head() ? `: ${head()}` : ""})`);
      err.kind = "answer";
      throw err;
    }
    return j;
  }

  // ---------------------------------------------------------------------------------------------
  // the shape of the server's answers: every field the page reads is checked before the answer
  // is used, so an answer that is JSON of another shape (another program on the port, another
  // version of mvem serve) is named, "the answer of /api/step lacks field series", instead of
  // failing as a script error ("Cannot convert undefined or null to object") or drawing half
  // a figure that a redraw on resize then fails on

  // a type of a field: a name of TYPES (a trailing "?": null too, as JSON writes a NaN), an
  // object spec {field: type} (a trailing "?" on a field's name: it may be absent or null), or
  // [spec]: an array whose every entry has that shape
  const TYPES = {
    number: [(v) => typeof v === "number", "a number"],
    string: [(v) => typeof v === "string", "a string"],
    boolean: [(v) => typeof v === "boolean", "true or false"],
    object: [(v) => v !== null && typeof v === "object" && !Array.isArray(v), "an object"],
    array: [Array.isArray, "an array"],
    numbers: [(v) => Array.isArray(v) && v.every((x) => x === null || typeof x === "number"), "an array of numbers"],
    strings: [(v) => Array.isArray(v) && v.every((x) => typeof x === "string"), "an array of strings"],
    complexes: [(v) => Array.isArray(v) && v.every((z) => z !== null && typeof z === "object" && typeof z.re === "number" && typeof z.im === "number"),
      "an array of {re, im}"],
  };
  const what = (v) => v === undefined ? "none" : v === null ? "null" : Array.isArray(v) ? "an array" : typeof v === "object" ? "an object"
    : `${typeof v} ${JSON.stringify(v).slice(0, 40)}`;
  function answerError(route, text) {
    const e = new Error(`the answer of ${route} ${text}`);
    e.kind = "answer";
    return e;
  }
  // `v` (the field `name` of the answer of `route`) checked against `type`
  function need(route, v, type, name) {
    const field = name ? `field ${name}` : "answer";
    if (typeof type === "string") {
      const nullable = type.endsWith("?");
      const [ok, words] = TYPES[type.replace("?", "")];
      if (!(ok(v) || (nullable && v === null))) throw answerError(route, `has ${field} of the wrong type (${what(v)}, expected ${words}${nullable ? " or null" : ""})`);
    } else if (Array.isArray(type)) {
      if (!Array.isArray(v)) throw answerError(route, `has ${field} of the wrong type (${what(v)}, expected an array)`);
      v.forEach((x, i) => need(route, x, type[0], `${name}[${i}]`));
    } else {
      if (!TYPES.object[0](v)) throw answerError(route, name ? `has ${field} of the wrong type (${what(v)}, expected an object)` : `is not a JSON object (${what(v)})`);
      for (const [k, t] of Object.entries(type)) {
        const opt = k.endsWith("?");
        const key = opt ? k.slice(0, -1) : k;
        const path = name ? `${name}.${key}` : key;
        if (v[key] === undefined || (opt && v[key] === null)) {
          if (opt) continue;
          throw answerError(route, `lacks field ${path}`);
        }
        need(route, v[key], t, path);
      }
    }
  }
  // every field of the object `obj` (the field `name`) an array of `n` numbers (a series per time)
  function sameLength(route, obj, name, n, of) {
    for (const [k, a] of Object.entries(obj)) {
      need(route, a, "numbers", `${name}.${k}`);
      if (a.length !== n) throw answerError(route, `has field ${name}.${k} of ${a.length} values for ${n} ${of}`);
    }
  }

  const SHAPE = {
    models: {
      params: "strings", cycles: "strings", modes: "strings", "units?": "object", "input_ranges?": "object",
      "controller_tuning?": { defaults: "object", fields: [{ name: "string", unit: "string", description: "string",
        "bounds?": { lo: "number", hi: "number", lo_open: "boolean", hi_open: "boolean", interval: "string" } }] },
    },
    steady: {
      physically_valid: "boolean", flags: "strings", eigenvalues: "complexes", "inputs?": "object",
      ...Object.fromEntries(SIGNALS.map(([n]) => [n, "number?"])),
    },
    linearize: {
      eigenvalues: "complexes", input_names: "strings", output_names: "strings", zeros: "object", "zero_errors?": "object",
      "dc_gain?": [["number?"]],
      "discrete?": { ts: "number", delays_s: { u_egr: "number", u_vgt: "number" },
        delay_samples: { u_egr: { whole: "number", remainder_s: "number" }, u_vgt: { whole: "number", remainder_s: "number" } },
        state_names: "strings", poles: "complexes" },
      // (the page always asks for the Bode diagram)
      frequency_response: { f_hz: "numbers", channels: "object" },
    },
    margins: { stable: "boolean", max_pole_all: "number?", "steady_state_warnings?": "strings", loops: [{ name: "string",
      ...Object.fromEntries(["alone", "others_closed"].map((k) => [k, { inert: "boolean", stable: "boolean", gain_margin: "number?",
        gain_margin_hz: "number?", phase_margin_deg: "number?", gain_crossover_hz: "number?", delay_margin_s: "number?",
        peak_sensitivity: "number?", peak_sensitivity_hz: "number?" }])) }] },
    step: { input: "string", input_unit: "string", from: "number", to: "number", t: "numbers", u: "numbers", "u_applied?": "numbers",
      "to_applied?": "number", series: "object", outputs: "object", "warnings?": "strings" },
    // an output's metrics (or its "error")
    stepOutput: { dc_gain: "number?", gain_sign: "string", y0: "number", y_final: "number", non_minimum_phase: "boolean",
      overshoot_pct: "number", rise_time: "number?", settling_time: "number?", "wrong_way?": { time: "number", value: "number", relative: "number" },
      "peak?": { time: "number", value: "number" } },
    map: { x: { input: "string", unit: "string", values: "numbers" }, y: { input: "string", unit: "string", values: "numbers" },
      channel: { input: "string", output: "string" }, dc_gain: "numbers", sign: "numbers", physically_valid: "array", errors: "array" },
    simulate: { source: "string", mode: "string", t: "numbers", series: "object",
      inputs: Object.fromEntries(INPUTS.map((n) => [n, "numbers"])), "inputs_applied?": Object.fromEntries(INPUTS.map((n) => [n, "numbers"])),
      stats: { steps: "number" }, "warnings?": "strings", "units?": "object", "passes?": "boolean", "violations?": "strings",
      "controller_tuning?": "object",
      // closed loop: mvem closed-loop's stats.json (a figure that does not apply is null)
      "cycle_stats?": { ...Object.fromEntries(["speed", "torque", "power"].map((k) => [k, { slope: "number?", r2: "number?", see: "number?", "not_applicable?": "string" }])),
        ...Object.fromEntries(["work_ref_kwh", "work_act_kwh", "work_error", "lambda_o_min", "lambda_o_min_t", "lambda_below_limit_share",
          "x_egr_rms_error", "pmep_mean_pa", "fuel_kg", "bsfc_g_kwh"].map((k) => [k, "number?"])),
        lambda_limit: "number", "not_applicable?": "strings" },
      "margins?": {
        summary: { every_s: "number", points: "number", analysed: "number", invalid_steady: "number", no_loop: "number", refused: "number",
          unstable_t: "numbers", loops: [{ name: "string", points: "number", unstable: "number", inert: "number",
            ...Object.fromEntries(["min_gain_margin", "min_phase_margin_deg", "max_peak_sensitivity"].map((k) => [`${k}?`, { value: "number", t: "number" }])) }] },
        samples: [{ t: "number", "loops?": [{ name: "string", others_closed: { gain_margin: "number?", phase_margin_deg: "number?" } }] }],
      },
    },
  };

  // each answer's check: its shape, and the lengths that must agree
  const CHECK = {
    models: (m) => {
      need("/api/models", m, SHAPE.models);
      for (const f of m.controller_tuning ? m.controller_tuning.fields : []) {
        const d = m.controller_tuning.defaults[f.name];
        if (!(typeof d === "number" || (Array.isArray(d) && d.length === 2 && d.every((x) => typeof x === "number")))) {
          throw answerError("/api/models", `has field controller_tuning.defaults.${f.name} of the wrong type (${what(d)}, expected a number or [kp, ki])`);
        }
      }
    },
    steady: (j) => need("/api/steady", j, SHAPE.steady),
    linearize: (j) => {
      const r = "/api/linearize";
      need(r, j, SHAPE.linearize);
      if (j.dc_gain && (j.dc_gain.length !== j.output_names.length || j.dc_gain.some((row) => row.length !== j.input_names.length))) {
        throw answerError(r, `has field dc_gain of another size than ${j.output_names.length} outputs x ${j.input_names.length} inputs`);
      }
      for (const [ch, z] of Object.entries(j.zeros)) need(r, z, "complexes?", `zeros.${ch}`);
      const fr = j.frequency_response;
      if (!fr.f_hz.length) throw answerError(r, "has field frequency_response.f_hz without a frequency");
      for (const [ch, g] of Object.entries(fr.channels)) {
        need(r, g, { mag: "numbers", phase_deg: "numbers" }, `frequency_response.channels.${ch}`);
        sameLength(r, g, `frequency_response.channels.${ch}`, fr.f_hz.length, "frequencies");
      }
    },
    margins: (j) => need("/api/margins", j, SHAPE.margins),
    step: (j) => {
      const r = "/api/step";
      need(r, j, SHAPE.step);
      if (!j.t.length) throw answerError(r, "has field t without a time");
      for (const k of ["u", "u_applied"]) {
        if (j[k] && j[k].length !== j.t.length) throw answerError(r, `has field ${k} of ${j[k].length} values for ${j.t.length} times`);
      }
      sameLength(r, j.series, "series", j.t.length, "times");
      for (const n of Object.keys(j.series)) {
        const m = j.outputs[n];
        if (m === undefined) throw answerError(r, `lacks field outputs.${n}`);
        if (m !== null && typeof m === "object" && typeof m.error === "string") continue;
        need(r, m, SHAPE.stepOutput, `outputs.${n}`);
        if (m.non_minimum_phase && !m.wrong_way) throw answerError(r, `lacks field outputs.${n}.wrong_way`);
      }
    },
    map: (j) => {
      const r = "/api/map";
      need(r, j, SHAPE.map);
      const n = j.x.values.length * j.y.values.length;
      if (j.x.values.length < 2 || j.y.values.length < 2) throw answerError(r, "has an axis of fewer than two values");
      for (const k of ["dc_gain", "sign", "physically_valid"]) {
        if (j[k].length !== n) throw answerError(r, `has field ${k} of ${j[k].length} values for ${n} grid points`);
      }
    },
    simulate: (j) => {
      const r = "/api/simulate";
      need(r, j, SHAPE.simulate);
      if (!j.t.length) throw answerError(r, "has field t without a time");
      sameLength(r, j.series, "series", j.t.length, "times");
      sameLength(r, j.inputs, "inputs", j.t.length, "times");
      if (j.inputs_applied) sameLength(r, j.inputs_applied, "inputs_applied", j.t.length, "times");
    },
  };

  // what went wrong, in a few words (the label of a failed steady state)
  function errorKind(e) {
    if (e.kind === "input") return "not a number";
    if (e.kind === "answer") return "unexpected answer";
    if (e.kind === "network") return "server unreachable";
    if (e.kind !== "http") return "error";
    return { 400: "refused: bad input", 422: "no equilibrium", 503: "server busy" }[e.status] || `error (HTTP ${e.status})`;
  }

  // the header's status: busy while any computation runs (each button's job counted, so one
  // that ends does not say "ready" while another still runs), else the standing errors, else
  // ready. The standing errors: a failed /api/models (`app.modelsError`: asked once, at the
  // start, so the menus lack what it lacked until the page is loaded again; it stays, the
  // other error beside it) and the latest other one (`app.statusError`: the steady state's,
  // or an unreachable server's, cleared when they succeed again)
  const jobs = new Map();
  let jobSeq = 0;
  app.statusError = null;
  app.modelsError = null;
  function setStatus(s, text) {
    const el = $("#status");
    el.dataset.status = s;
    el.textContent = text || s;
  }
  function refreshStatus() {
    if (jobs.size) {
      const texts = [...jobs.values()];
      setStatus("busy", texts[texts.length - 1] + (jobs.size > 1 ? ` (${jobs.size} computations)` : ""));
    } else if (app.statusError || app.modelsError) {
      setStatus("error", [app.modelsError, app.statusError?.text].filter(Boolean).join("; "));
    } else {
      setStatus("ok", "ready");
    }
  }

  function showError(id, e) {
    const el = $(id);
    if (e) { el.textContent = String(e.message || e); el.hidden = false; } else { el.hidden = true; el.textContent = ""; }
  }

  // the number in the number field `name`, or an error naming the field (`label`): blank, or
  // an entry the browser cannot read as a number (it holds "1e400" or "15abc" as ""), is not
  // a 0 (Number("") is 0): no request goes out with it
  function num(name, label = name) {
    const el = $(`input[name=${name}]`);
    const s = el.value.trim();
    const v = s === "" ? NaN : Number(s);
    if (!Number.isFinite(v)) {
      const why = s !== "" ? `"${s}"` : el.validity.badInput ? "an entry the browser cannot read as one" : "empty";
      const e = new Error(`${label}: not a number (${why})`);
      e.kind = "input";
      throw e;
    }
    return v;
  }

  // an optional number field: undefined when left empty (an entry that is not a number is
  // an error naming it)
  function optNum(name, label = name) {
    const el = $(`input[name=${name}]`);
    return el.value.trim() === "" && !el.validity.badInput ? undefined : num(name, label);
  }

  // the operating point of the four number fields (an error naming a field that holds no number)
  function point() {
    const p = {};
    for (const n of INPUTS) p[n] = num(n);
    return p;
  }
  // the same without the check (a field without a number is null): the key of a shown result
  function pointKey() {
    const p = {};
    for (const n of INPUTS) {
      const s = $(`input[name=${n}]`).value.trim();
      p[n] = s === "" ? null : Number(s);
    }
    return p;
  }
  const modelSel = () => ({ model: Number($("select[name=model]").value), params: $("select[name=params]").value || undefined });

  // the browser's download of `text` as the file `name`
  function saveFile(name, text, type) {
    const a = document.createElement("a");
    a.href = URL.createObjectURL(new Blob([text], { type }));
    a.download = name;
    document.body.appendChild(a);
    a.click();
    setTimeout(() => { URL.revokeObjectURL(a.href); a.remove(); }, 0);
  }

  function download(name, rows) {
    const text = rows.map((r) => r.map((c) => (typeof c === "string" && /[",\n]/.test(c)) ? `"${c.replace(/"/g, '""')}"` : String(c ?? "")).join(",")).join("\n") + "\n";
    saveFile(name, text, "text/csv");
  }

  // a complex number {re, im} as "-1.23" or "-1.23+4.56i"
  const cplx = (e) => e.im === 0 ? fmt(e.re) : `${fmt(e.re)}${e.im < 0 ? "−" : "+"}${fmt(Math.abs(e.im))}i`;

  // ---------------------------------------------------------------------------------------------
  // steady state: debounced, at most one request in flight, the latest inputs always win

  let debounce = 0;
  function scheduleSteady() {
    clearTimeout(debounce);
    debounce = setTimeout(requestSteady, 10);
    markStale();
  }

  async function requestSteady() {
    if (app.inflight) { app.again = true; return; }
    app.inflight = true;
    const seq = ++app.seq;
    try {
      const q = new URLSearchParams({ ...point(), model: modelSel().model });
      if (modelSel().params) q.set("params", modelSel().params);
      const j = await api(`/api/steady?${q}`);
      CHECK.steady(j);
      showSteady(j, seq);
      app.steadyFailed = null;
      showError("#steady-error", null);
      $("table.signals").dataset.stale = "false";
      // (a failed /api/models stands apart, app.modelsError: the menus lack what it lacked)
      app.statusError = null;
      refreshStatus();
    } catch (e) {
      // the label says what failed; the values left in the table are marked as the last
      // point's, and the header shows the error
      showError("#steady-error", e);
      const kind = errorKind(e);
      $("#validity").dataset.valid = "";
      $("#validity").dataset.error = e.kind === "http" ? String(e.status) : (e.kind || "error");
      $("#validity").textContent = app.steady ? `${kind} (the values below are of the last point computed)` : kind;
      $("table.signals").dataset.stale = "true";
      app.steadyFailed = e.kind || "error";
      app.statusError = { source: "steady", text: `steady state: ${kind}` };
      refreshStatus();
    } finally {
      app.inflight = false;
      if (app.again) { app.again = false; requestSteady(); }
    }
  }

  function showSteady(j, seq) {
    app.steady = j;
    for (const [n] of SIGNALS) {
      const td = $(`[data-signal="${n}"]`);
      if (!td) continue;
      const v = j[n];
      td.dataset.value = v === undefined ? "" : String(v);
      td.textContent = fmt(v);
    }
    const ok = j.physically_valid === true;
    delete $("#validity").dataset.error;
    $("#validity").dataset.valid = String(ok);
    $("#validity").textContent = ok ? "✓ physically valid" : "✗ NOT physically valid";
    const flags = $("#flags");
    flags.dataset.flags = (j.flags || []).join(";");
    flags.replaceChildren(...(j.flags || []).map((f) => {
      const s = document.createElement("span");
      s.className = "flag" + (f.startsWith("saturation") || f.startsWith("lambda") ? " invalidating" : "");
      s.textContent = f;
      return s;
    }));
    if (!(j.flags || []).length) flags.textContent = "no flags";
    showClamped(j);
    $("#eigenvalues").textContent = (j.eigenvalues || []).map(cplx).join(", ");
    app.shown = seq;
    document.body.dataset.steadySeq = String(seq);
    if (document.body.dataset.state !== "ready") {
      // time from navigation start to the first values shown (page interactive)
      document.body.dataset.readyMs = performance.now().toFixed(1);
      document.body.dataset.state = "ready";
    }
  }

  // an input outside the parameter set's range: the model clamps it (the authors' saturation),
  // and the values shown are those of the clamped input; said in words, not only by the flag
  // "input:n_e in input_saturation.n_e" (the answer's "inputs" as given, n_e ... as applied)
  const INPUT_KEYS = { n_e: "n_e_rpm", u_delta: "u_delta_mg", u_egr: "u_egr_pct", u_vgt: "u_vgt_pct" };
  const INPUT_UNITS = { n_e: "rpm", u_delta: "mg/cycle", u_egr: "%", u_vgt: "%" };
  function showClamped(j) {
    const el = $("#steady-clamped");
    const range = (app.inputRanges || {})[$("select[name=params]").value] || {};
    const clamped = INPUTS.filter((n) => j.inputs && typeof j[n] === "number" && j.inputs[INPUT_KEYS[n]] !== j[n]);
    el.dataset.clamped = clamped.join(",");
    el.textContent = clamped.map((n) => {
      const u = INPUT_UNITS[n];
      const r = Array.isArray(range[n]) ? ` [${range[n][0]}, ${range[n][1]}] ${u}` : "";
      const used = `${tickLabel(j[n])} ${u}`;
      return `${n} ${tickLabel(j.inputs[INPUT_KEYS[n]])} ${u} is outside the parameter set's range${r}: the model clamps it to ${used} (the authors' saturation), the values below are at ${used}`;
    }).join("; ");
  }

  function buildSignalTable() {
    const tb = $("#signals");
    tb.replaceChildren(...SIGNALS.map(([n, d]) => {
      const tr = document.createElement("tr");
      tr.innerHTML = `<td>${n}</td><td class="v" data-signal="${n}">–</td><td class="u">${unit(n)}</td><td class="d">${d}</td>`;
      return tr;
    }));
  }

  function wireInputs() {
    for (const n of INPUTS) {
      const num = $(`input[name=${n}]`);
      const sl = $(`input[data-slider=${n}]`);
      sl.addEventListener("input", () => { num.value = sl.value; scheduleSteady(); });
      // (a field without a number is named by the steady state's error, no request made)
      num.addEventListener("input", () => {
        const v = Number(num.value);
        if (num.value !== "" && Number.isFinite(v)) sl.value = String(v);
        scheduleSteady();
      });
    }
    $("select[name=model]").addEventListener("change", scheduleSteady);
    $("select[name=params]").addEventListener("change", () => {
      applyInputRanges();
      // a map axis follows the parameter set's range of its input
      for (const a of ["x", "y"]) if (RANGED_INPUTS.includes($(`select[name=map_${a}]`).value)) applyMapRange(a);
      scheduleSteady();
    });
    for (const a of ["x", "y"]) $(`select[name=map_${a}]`).addEventListener("change", () => applyMapRange(a));
  }

  // a map axis's range when its input is chosen: the input's slider range (the parameter
  // set's) one slider step inside its ends, as the defaults (u_egr 0.5-99.5 %, u_vgt
  // 20.5-99.5 % with the authors' ranges: the saturation's kinks at the ends have no DC gain)
  function applyMapRange(axis) {
    const sl = $(`input[data-slider=${$(`select[name=map_${axis}]`).value}]`);
    const step = Number(sl.step) || 0;
    const round = (v) => String(Number(v.toPrecision(12)));
    $(`input[name=map_${axis}_lo]`).value = round(Number(sl.min) + step);
    $(`input[name=map_${axis}_hi]`).value = round(Number(sl.max) - step);
  }

  // the inputs' sliders span the selected parameter set's input saturation (/api/models
  // "input_ranges"; the authors' 500-2000 rpm, 1-250 mg, 0-100 % EGR and 20-100 % VGT by
  // default); the number fields take any value (the model clamps it, as the warnings of the
  // CLI say)
  const RANGED_INPUTS = ["n_e", "u_delta", "u_egr", "u_vgt"];
  function applyInputRanges() {
    const r = (app.inputRanges || {})[$("select[name=params]").value];
    if (!r) return;
    for (const n of RANGED_INPUTS) {
      if (!Array.isArray(r[n])) continue;
      const sl = $(`input[data-slider=${n}]`);
      sl.min = String(r[n][0]);
      sl.max = String(r[n][1]);
      sl.value = $(`input[name=${n}]`).value;
    }
  }

  // ---------------------------------------------------------------------------------------------
  // plotting

  const COLORS = ["#1f6feb", "#d1495b", "#2e7d32", "#8e44ad", "#e67e22", "#00897b", "#6d4c41", "#546e7a"];

  function niceRange(lo, hi) {
    if (!(Number.isFinite(lo) && Number.isFinite(hi))) return [0, 1];
    if (lo === hi) { const d = Math.abs(lo) * 0.01 || 1; return [lo - d, hi + d]; }
    const pad = (hi - lo) * 0.08;
    return [lo - pad, hi + pad];
  }

  // about n ticks at a step of 1, 2 or 5 times a power of ten, at least two of them: one tick
  // alone gives no scale (a step's n_t axis had only "13350", a cycle's lambda_O strip "5");
  // where there would be one, the largest step of 5, 2.5, 2, 1 ... times a power of ten that
  // gives two (not simply more ticks: a 46 px strip got four, "2 4 6 8", their labels touching)
  function ticks(lo, hi, n) {
    const step0 = (hi - lo) / n;
    const mag0 = Math.pow(10, Math.floor(Math.log10(step0)));
    const t = ticksAt(lo, hi, [1, 2, 5, 10].map((k) => k * mag0).find((s) => s >= step0) || step0);
    if (t.length >= 2) return t;
    const mag = Math.pow(10, Math.floor(Math.log10(hi - lo)));
    for (const k of [5, 2.5, 2, 1, 0.5, 0.25, 0.2, 0.1]) {
      const u = ticksAt(lo, hi, k * mag);
      if (u.length >= 2) return u;
    }
    return t;
  }
  function ticksAt(lo, hi, step) {
    if (!(step > 0 && Number.isFinite(step))) return [];
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(Math.abs(v) < step * 1e-9 ? 0 : v);
    return out;
  }

  // ticks of an angle [deg]: steps of 15, 30, 45, 90, 180 or 360 deg (multiples of 360 beyond)
  function degTicks(lo, hi, n) {
    const step0 = (hi - lo) / n;
    if (step0 < 5) return ticks(lo, hi, n);
    const step = [5, 10, 15, 30, 45, 90, 180, 360].find((s) => s >= step0) || 360 * Math.pow(2, Math.ceil(Math.log2(step0 / 360)));
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) out.push(v);
    return out;
  }

  // the unit of a gain: output unit per input unit ("1" for a dimensionless output, a
  // compound input unit in parentheses: "kg/s/(mg/cycle)", "1/%")
  function ratioUnit(out, inp) {
    const o = !out || out === "-" ? "1" : out;
    const i = !inp || inp === "-" ? "" : (inp.includes("/") ? `(${inp})` : inp);
    return i ? `${o}/${i}` : o;
  }

  function tickLabel(v) {
    const a = Math.abs(v);
    if (a !== 0 && (a < 1e-3 || a >= 1e7)) return v.toExponential(2);
    return String(Number(v.toPrecision(6)));
  }

  // the range of the values between the quantiles q and 1 - q (spikes of a drive cycle, such as
  // lambda_O at zero fuel, would flatten everything else)
  function robustRange(arrays, q) {
    const all = [];
    for (const y of arrays) for (const v of y) if (Number.isFinite(v)) all.push(v);
    if (!all.length) return [0, 1];
    all.sort((a, b) => a - b);
    const at = (p) => all[Math.min(all.length - 1, Math.max(0, Math.round(p * (all.length - 1))))];
    return [at(q), at(1 - q)];
  }

  // a panel's title on one line, never cut at the canvas's edge: from `start` (over the plot) at
  // 12, 11 or 10 px, whichever fits before `right`; else at 10 px from `left` (over the y tick
  // labels, whose top label starts below a 10 px title), condensed to the width if need be
  function fitTitle(ctx, title, left, start, right, y) {
    for (const size of [12, 11, 10]) {
      ctx.font = `${size}px system-ui, sans-serif`;
      if (ctx.measureText(title).width <= right - start) { ctx.fillText(title, start, y); return; }
    }
    ctx.fillText(title, left, y, right - left);
  }

  // one panel: frame, ticks, title; returns the coordinate maps
  // (opts.logX: the x values are log10 of the quantity; ticks at the decades, labelled 10^x;
  // opts.yTicks: about so many y ticks, default 3; opts.xLabel: the x axis's name and unit, left
  // of its first tick label)
  function panel(ctx, box, xr, yr, title, opts = {}) {
    const [x0, y0, w, h] = box;
    const L = 56, R = 8, T = 16, B = 18;
    const px = (x) => x0 + L + (x - xr[0]) / (xr[1] - xr[0]) * (w - L - R);
    const py = (y) => y0 + T + (1 - (y - yr[0]) / (yr[1] - yr[0])) * (h - T - B);
    ctx.save();
    ctx.strokeStyle = "#c9ced8"; ctx.lineWidth = 1;
    ctx.strokeRect(x0 + L, y0 + T, w - L - R, h - T - B);
    ctx.fillStyle = "#5d6778"; ctx.font = "11px system-ui, sans-serif";
    ctx.textAlign = "right"; ctx.textBaseline = "middle";
    const yTicks = (opts.yTickFn || ticks)(yr[0], yr[1], opts.yTicks || 3);
    for (const v of yTicks) {
      ctx.fillText(tickLabel(v), x0 + L - 4, py(v));
      ctx.strokeStyle = "#eef0f4"; ctx.beginPath(); ctx.moveTo(x0 + L, py(v)); ctx.lineTo(x0 + w - R, py(v)); ctx.stroke();
    }
    ctx.textBaseline = "top";
    // an x tick label centred under its tick, or ending at the canvas's right edge where
    // centred it would be cut there (the last tick of a cycle at its end, "300" at 300 s)
    const xTick = (text, X) => {
      ctx.textAlign = X + ctx.measureText(text).width / 2 > x0 + w ? "right" : "center";
      ctx.fillText(text, ctx.textAlign === "right" ? Math.min(X, x0 + w) : X, y0 + h - B + 3);
    };
    if (opts.logX) {
      for (let v = Math.ceil(xr[0]); v <= xr[1] + 1e-9; v++) {
        xTick(tickLabel(Number(Math.pow(10, v).toPrecision(6))), px(v));
        ctx.save(); ctx.strokeStyle = "#eef0f4"; ctx.beginPath(); ctx.moveTo(px(v), y0 + T); ctx.lineTo(px(v), y0 + h - B); ctx.stroke(); ctx.restore();
      }
    } else {
      for (const v of ticks(xr[0], xr[1], 6)) xTick(tickLabel(v), px(v));
    }
    if (opts.xLabel) { ctx.textAlign = "right"; ctx.fillText(opts.xLabel, x0 + L - 8, y0 + h - B + 3); }
    ctx.fillStyle = "#1d2330"; ctx.textAlign = "left"; ctx.textBaseline = "top";
    fitTitle(ctx, title, x0 + 4, x0 + L + 4, x0 + w - R, y0 + 2);
    ctx.restore();
    return { px, py, clip: [x0 + L, y0 + T, w - L - R, h - T - B], yTicks: yTicks.length };
  }

  function line(ctx, p, xs, ys, color, width = 1.5, dash = []) {
    ctx.save();
    ctx.beginPath(); ctx.rect(...p.clip); ctx.clip();
    ctx.strokeStyle = color; ctx.lineWidth = width; ctx.setLineDash(dash);
    ctx.beginPath();
    let started = false;
    for (let i = 0; i < xs.length; i++) {
      if (!Number.isFinite(ys[i])) { started = false; continue; }
      const X = p.px(xs[i]), Y = p.py(ys[i]);
      if (started) ctx.lineTo(X, Y); else { ctx.moveTo(X, Y); started = true; }
    }
    ctx.stroke();
    ctx.restore();
  }

  // a mark (the NMP excursion's red dot, the overshoot's orange triangle) and its label. The
  // label was always drawn right of the mark at its height, so a peak close to the final value
  // put it on the dashed final-value line ("overshoot 18.9 %" struck through by it, on the
  // curve too). It is placed now where it touches neither the lines at the heights `place.lines`
  // (pixels: the steady values before and after) nor a label placed before (`place.taken`,
  // boxes), inside the plot area `place.clip`: of beside the mark, then above or below it at
  // growing distances, right or left of it, the nearest over the fewest points of the curve
  // (`place.curve`, pixels); one moved off the mark's height gets a thin line to the mark
  function marker(ctx, X, Y, color, label, shape, place) {
    ctx.save();
    ctx.fillStyle = color; ctx.strokeStyle = "#fff"; ctx.lineWidth = 1;
    ctx.beginPath();
    if (shape === "tri") { ctx.moveTo(X, Y - 6); ctx.lineTo(X - 5, Y + 4); ctx.lineTo(X + 5, Y + 4); ctx.closePath(); }
    else ctx.arc(X, Y, 4.5, 0, 2 * Math.PI);
    ctx.fill(); ctx.stroke();
    ctx.font = "bold 11px system-ui, sans-serif"; ctx.textBaseline = "middle"; ctx.textAlign = "left";
    const w = ctx.measureText(label).width, H = 12;
    const [cx, cy, cw, ch] = place.clip;
    // (the mark itself: another label keeps off it too)
    place.taken.push([X - 6, Y - 7, 12, 14]);
    const meets = (a, b) => a[0] < b[0] + b[2] && b[0] < a[0] + a[2] && a[1] < b[1] + b[3] && b[1] < a[1] + a[3];
    let best = null;
    for (const dy of [0, -9, 9, -13, 13, -17, 17, -21, 21, -27, 27, -33, 33, -40, 40]) {
      for (const side of [1, -1]) {
        const box = [side > 0 ? X + 8 : X - 8 - w, Y + dy - H / 2, w, H];
        if (box[0] < cx + 1 || box[0] + w > cx + cw - 1 || box[1] < cy + 1 || box[1] + H > cy + ch - 1) continue;
        if (place.lines.some((ly) => ly >= box[1] - 2 && ly <= box[1] + H + 2)) continue;
        if (place.taken.some((b) => meets(b, box))) continue;
        const hits = place.curve.reduce((n, [px, py]) => n + (px >= box[0] - 2 && px <= box[0] + w + 2 && py >= box[1] - 2 && py <= box[1] + H + 2 ? 1 : 0), 0);
        const cost = 1000 * hits + Math.abs(dy) + (side < 0 ? 6 : 0);
        if (!best || cost < best.cost) best = { cost, box, dy };
      }
    }
    // (no place clear of the lines in a panel too small: beside the mark, as before)
    if (!best) best = { box: [X + 8, Y - H / 2, w, H], dy: 0 };
    const [bx, by] = best.box;
    if (Math.abs(best.dy) > 9) {
      ctx.strokeStyle = color; ctx.lineWidth = 0.8; ctx.beginPath();
      ctx.moveTo(X, Y); ctx.lineTo(bx < X ? bx + w : bx, by + H / 2); ctx.stroke();
    }
    ctx.fillStyle = color;
    ctx.fillText(label, bx, by + H / 2);
    place.taken.push(best.box);
    ctx.restore();
  }

  // a canvas drawn at the size it is shown: the width of its panel and the height of its
  // HTML attribute (fixed, so the 11-12 px text stays so at any width) in CSS pixels, its
  // bitmap that times devicePixelRatio (sharp on a high-density screen, not scaled down on a
  // narrow one); the drawing's size in CSS pixels is c.drawW x c.drawH. Returns the context,
  // scaled to CSS pixels, cleared to white.
  function clearCanvas(c) {
    if (!c.dataset.height) c.dataset.height = c.getAttribute("height");
    c.style.height = `${c.dataset.height}px`;
    // (inside the border)
    const W = c.clientWidth || Number(c.getAttribute("width"));
    const H = c.clientHeight || Number(c.dataset.height);
    const dpr = window.devicePixelRatio || 1;
    c.width = Math.round(W * dpr);
    c.height = Math.round(H * dpr);
    c.drawW = W; c.drawH = H;
    const ctx = c.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, W, H);
    return ctx;
  }

  // a copy of the canvas's bitmap, and the canvas restored from one (the time cursor moves
  // over the drawn figure: drawImage, not getImageData, which would want willReadFrequently)
  function snapshot(c) {
    const s = document.createElement("canvas");
    s.width = c.width; s.height = c.height;
    s.getContext("2d").drawImage(c, 0, 0);
    return s;
  }
  function restore(c, snap) {
    const ctx = c.getContext("2d");
    ctx.save(); ctx.setTransform(1, 0, 0, 1, 0, 0); ctx.drawImage(snap, 0, 0); ctx.restore();
    return ctx;
  }

  // ---------------------------------------------------------------------------------------------
  // linear model panel (/api/linearize: the object of `mvem linearize --json`, with `ts` its
  // "discrete" part)

  // right half plane, as `mvem linearize` marks it
  const isRhp = (z) => z.re > 1e-9 * (1 + Math.hypot(z.re, z.im));

  // what a result was asked for (the point, model, parameter set and, for the loop margins and a
  // closed-loop run, the controller tuning of the drive-cycle panel's form), as a key (JSON) and
  // as text
  const pointStamp = () => JSON.stringify({ point: pointKey(), ...modelSel() });
  // the tuning form's entries as typed (a number, or the text of one that is none)
  const tuningKey = () => app.tuningDefaults
    ? $$("input[data-tuning]").map((i) => { const v = Number(i.value); return i.value.trim() !== "" && Number.isFinite(v) ? v : i.value; })
    : undefined;
  const marginsStamp = () => JSON.stringify({ point: pointKey(), ...modelSel(), tuning: tuningKey() });
  // (the tuning only matters to a closed-loop run: `mode` the run's, by default the shown one's)
  const cycleStamp = (mode = app.cycle && app.cycle.mode) => JSON.stringify({ ...modelSel(), tuning: mode === "closed" ? tuningKey() : undefined });
  function pointText() {
    const p = point();
    return `at n_e ${p.n_e} rpm, u_delta ${p.u_delta} mg/cycle, u_egr ${p.u_egr} %, u_vgt ${p.u_vgt} %, ${modelSel().model} states, parameters ${$("select[name=params]").value}`;
  }
  // the parts of a key that changed, as words ("the point", "the parameter set" ...)
  const KEY_PARTS = { point: "the point", model: "the model", params: "the parameter set", tuning: "the controller tuning" };
  function changedParts(was, now) {
    const a = JSON.parse(was), b = JSON.parse(now);
    return Object.keys(KEY_PARTS).filter((k) => JSON.stringify(a[k]) !== JSON.stringify(b[k])).map((k) => KEY_PARTS[k]);
  }
  // each result panel's line naming what its result was computed at (the panel: its line, the
  // key of what it depends on, its button). A result of another point, model, parameter set
  // (or tuning) than the inputs' is marked, naming what changed (not recomputed: the sliders
  // would ask for one per move), and so is one whose next computation failed
  const STAMPS = {
    linear: ["#lin-at", pointStamp, "Linearize"],
    margins: ["#margins-at", marginsStamp, "Loop margins"],
    step: ["#step-at", pointStamp, "Run step"],
    map: ["#map-at", pointStamp, "Compute map"],
    cycle: ["#cycle-at", cycleStamp, "Run cycle"],
  };
  const stamps = {};
  function stamp(panel, key, text) {
    stamps[panel] = { key, text, failed: false };
    markStale();
    scheduleUrl();
  }
  function markStale() {
    for (const [panel, st] of Object.entries(stamps)) {
      const [sel, keyOf, button] = STAMPS[panel];
      const el = $(sel);
      const changed = changedParts(st.key, keyOf());
      el.dataset.stale = String(changed.length > 0 || st.failed);
      el.textContent = st.failed ? `${st.text}; the last ${button} failed: this is the result before it`
        : changed.length ? `${st.text}; ${changed.join(" and ")} ${changed.length > 1 ? "have" : "has"} changed: ${button} again` : st.text;
    }
  }

  // a button's computation: the button disabled and the status busy meanwhile; its panel's
  // error line cleared when it succeeds, showing the failure when it throws
  async function busy(button, text, errorId, work, panel) {
    const btn = $(button);
    btn.disabled = true;
    const id = ++jobSeq;
    jobs.set(id, text);
    refreshStatus();
    try {
      await work();
      showError(errorId, null);
      if (app.statusError && app.statusError.source === "network") app.statusError = null;
      // the server answers again: the steady state that failed for want of it is asked again
      // (the header said "ready" beside a table still marked "server unreachable")
      if (app.steadyFailed === "network") requestSteady();
    } catch (e) {
      showError(errorId, e);
      // the result shown stays, marked as the one before
      if (panel && stamps[panel]) { stamps[panel].failed = true; markStale(); }
      if (e.kind === "network") app.statusError = { source: "network", text: "server unreachable" };
    } finally {
      btn.disabled = false;
      jobs.delete(id);
      // (a panel a link asked for: in the link now by its result, or not after a failure)
      if (panel === "cycle") app.urlCycleT = undefined;
      if (panel === "linear") app.urlBode = undefined;
      if (panel && app.urlPending.delete(panel)) scheduleUrl();
      refreshStatus();
    }
  }

  async function runLinearize() {
    await busy("[data-action=linearize]", "linearizing…", "#lin-error", async () => {
      const q = new URLSearchParams({ ...point(), model: modelSel().model });
      if (modelSel().params) q.set("params", modelSel().params);
      const ts = optNum("lin_ts", "sample time");
      if (ts !== undefined) q.set("ts", String(ts));
      q.set("bode", bodeGrid());
      const key = pointStamp();
      const at = pointText();
      const j = await api(`/api/linearize?${q}`);
      CHECK.linearize(j);
      app.linear = j;
      stamp("linear", key, at);
      showLinear(j);
      $("[data-download=linear]").disabled = false;
    }, "linear");
  }

  // the frequency grid of the Bode diagram (Hz: from, to, points): the range of the two inputs
  // (empty: 0.01 and 100 Hz), checked by the server (a bad range is its 400, naming `bode`)
  const BODE_POINTS = 200;
  function bodeGrid() {
    const v = (name, label, dflt) => optNum(name, label) ?? dflt;
    return `${v("bode_fmin", "Bode from", 0.01)}:${v("bode_fmax", "Bode to", 100)}:${BODE_POINTS}`;
  }

  // the channel menu of the Bode diagram (the previous choice kept when the new model has it)
  function showBodeChannels(j) {
    const fr = j.frequency_response;
    $("#lin-bode-controls").hidden = !fr;
    $("[data-plot=bode]").hidden = !fr;
    if (!fr) return;
    const sel = $("select[name=bode_channel]");
    const names = Object.keys(fr.channels);
    let keep = names.includes(sel.value) ? sel.value : (names.includes("u_vgt->W_c") ? "u_vgt->W_c" : names[0]);
    // the channel of a link, once its linear model is there
    if (app.urlBode !== undefined) {
      if (names.includes(app.urlBode)) keep = app.urlBode;
      else addUrlProblem("bode_channel", `${quoted(app.urlBode)} is not a channel of the linear model`);
      app.urlBode = undefined;
    }
    sel.replaceChildren(...names.map((n) => {
      const o = document.createElement("option");
      o.value = n; o.textContent = n.replace("->", " → ");
      return o;
    }));
    sel.value = keep;
    drawBode();
  }

  // magnitude [dB] and phase [deg] of the chosen channel over log f
  function drawBode() {
    const j = app.linear;
    const fr = j && j.frequency_response;
    if (!fr) return;
    const ch = $("select[name=bode_channel]").value;
    const g = fr.channels[ch];
    if (!g) return;
    const [inp, out] = ch.split("->");
    const c = $("[data-plot=bode]");
    const ctx = clearCanvas(c);
    const lf = fr.f_hz.map((f) => Math.log10(f));
    const xr = [lf[0], lf[lf.length - 1]];
    // (a zero gain is -inf dB: the range of the finite values; none: a channel without gain)
    const db = g.mag.map((m) => 20 * Math.log10(m));
    const fin = db.filter(Number.isFinite);
    const w = c.drawW / 2;
    const units = ratioUnit(unit(out), unit(inp));
    const pm = panel(ctx, [0, 0, w, c.drawH], xr, fin.length ? niceRange(Math.min(...fin), Math.max(...fin)) : [-1, 1],
      `|G| [dB re 1 ${units}]   f [Hz]`, { logX: true, yTicks: 5 });
    // the 0 dB line (|G| = 1 in the channel's units)
    if (fin.length && Math.min(...fin) <= 0 && Math.max(...fin) >= 0) line(ctx, pm, xr, [0, 0], "#5d6778", 1, [4, 3]);
    line(ctx, pm, lf, db, COLORS[0], 2);
    c.dataset.zeroGain = fin.length ? (fin.length < db.length ? "some" : "") : "all";
    if (fin.length < db.length) {
      ctx.save();
      ctx.fillStyle = "#c62828"; ctx.font = "12px system-ui, sans-serif"; ctx.textAlign = "center"; ctx.textBaseline = "middle";
      const [cx, cy, cw, chh] = pm.clip;
      ctx.fillText(fin.length ? "|G| = 0 (−∞ dB) at some frequencies: gaps in the line" : "zero gain: |G| = 0 (−∞ dB) at every frequency",
        cx + cw / 2, fin.length ? cy + 10 : cy + chh / 2);
      ctx.restore();
    }
    const ph = g.phase_deg.filter(Number.isFinite);
    const pp = panel(ctx, [w, 0, w, c.drawH], xr, ph.length ? niceRange(Math.min(...ph), Math.max(...ph)) : [-1, 1],
      "phase [deg]   f [Hz]", { logX: true, yTicks: 6, yTickFn: degTicks });
    line(ctx, pp, lf, g.phase_deg, COLORS[1], 2);
    const [f0, f1] = [fr.f_hz[0], fr.f_hz[fr.f_hz.length - 1]];
    const hz = (f) => String(Number(f.toPrecision(6)));
    $("#bode-range").textContent = `${hz(f0)} to ${hz(f1)} Hz`;
    c.dataset.range = `${f0}:${f1}`;
    c.dataset.drawn = ch;
  }

  // the baseline's air-path loop margins at the inputs' point (POST /api/margins, as
  // mvem margins), with the tuning of the drive-cycle panel's form
  async function runMargins() {
    await busy("[data-action=margins]", "loop margins…", "#margins-error", async () => {
      const body = { point: point(), ...modelSel() };
      const key = marginsStamp();
      const at = pointText();
      // the tuning of the drive-cycle panel's form (shown in closed-loop mode): the summary
      // says which entries differ from the defaults
      let tuning = "";
      if (app.tuningDefaults) {
        body.tuning = tuningValue();
        const changed = Object.keys(body.tuning).filter((k) => JSON.stringify(body.tuning[k]) !== JSON.stringify(app.tuningDefaults[k]));
        tuning = changed.length ? `; controller tuning of the drive-cycle panel's form (closed loop): ${changed.join(", ")} changed` : "; controller tuning: the defaults";
      }
      const j = await api("/api/margins", body);
      CHECK.margins(j);
      app.margins = j;
      stamp("margins", key, at);
      showMargins(j, tuning);
    }, "margins");
  }

  function showMargins(j, tuning = "") {
    // (the point, model and parameter set are on the #margins-at line above)
    $("#margins-summary").textContent = `every loop closed ${j.stable ? "stable" : "UNSTABLE"} (largest closed-loop pole |z| = ${fmt(j.max_pole_all)})${(j.steady_state_warnings || []).length ? `; warning: the steady state is not physically valid (${j.steady_state_warnings.join(", ")})` : ""}${tuning}`;
    $("#margins-summary").dataset.stable = String(j.stable);
    const hz = (f) => f === null ? "–" : `${Number(f.toPrecision(4))} Hz`;
    const rows = [];
    for (const l of j.loops) {
      for (const [other, m] of [["open", l.alone], ["closed", l.others_closed]]) {
        const tr = document.createElement("tr");
        tr.dataset.loop = l.name;
        tr.dataset.other = other;
        tr.dataset.gainMargin = m.gain_margin === null ? "" : String(m.gain_margin);
        tr.dataset.phaseMargin = m.phase_margin_deg === null ? "" : String(m.phase_margin_deg);
        const gm = m.inert ? "no effect at this point" : !m.stable ? "unstable" : m.gain_margin === null ? "none up to 1e4"
          : `${fmt(m.gain_margin)} (${(20 * Math.log10(m.gain_margin)).toFixed(1)} dB) at ${hz(m.gain_margin_hz)}`;
        const pm = m.inert || !m.stable ? "–" : m.phase_margin_deg === null ? "no crossover"
          : `${m.phase_margin_deg.toFixed(1)} deg at ${hz(m.gain_crossover_hz)}`;
        const dm = !m.stable || m.delay_margin_s === null ? "–" : `${Number(m.delay_margin_s.toPrecision(4))} s`;
        tr.append(cell("", l.name.replace("->", " → ")), cell("", other), cell("", gm), cell("", pm), cell("", dm),
          cell("", `${fmt(m.peak_sensitivity)} at ${hz(m.peak_sensitivity_hz)}`));
        if (!m.stable) tr.className = "bad";
        rows.push(tr);
      }
    }
    $("#margins tbody").replaceChildren(...rows);
    $("#margins").hidden = false;
  }

  function showLinear(j) {
    showBodeChannels(j);
    $("#lin-poles").textContent = j.eigenvalues.map(cplx).join(", ");
    const d = j.discrete;
    $("#lin-sampled").hidden = !d;
    if (d) {
      $("#lin-ts").textContent = String(d.ts);
      const ds = (k) => `${k} delay ${d.delays_s[k]} s = ${d.delay_samples[k].whole} samples + ${Math.round(d.delay_samples[k].remainder_s * 1e9) / 1e6} ms`; // to 1 ns, as the CLI
      $("#lin-delays").textContent = `${ds("u_egr")}, ${ds("u_vgt")} (${d.state_names.length} states with the delay registers)`;
      $("#lin-dpoles").textContent = d.poles.map((z) => fmt(Math.hypot(z.re, z.im))).join(", ");
    }
    const outs = j.output_names;
    const th = document.createElement("tr");
    th.append(...["input → output", ...outs].map((n) => {
      const h = document.createElement("th");
      h.textContent = n;
      return h;
    }));
    $("#lin-channels thead").replaceChildren(th);
    $("#lin-channels tbody").replaceChildren(...j.input_names.map((inp, i) => {
      const tr = document.createElement("tr");
      tr.append(cell("", inp));
      outs.forEach((out, o) => {
        const ch = `${inp}->${out}`;
        const g = j.dc_gain ? j.dc_gain[o][i] : null;
        const td = cell("", "");
        const gain = document.createElement("span");
        gain.className = "g";
        gain.textContent = fmt(g);
        td.append(gain);
        td.dataset.channel = ch;
        td.dataset.dcGain = g === null ? "" : String(g);
        const zs = j.zeros[ch];
        const extra = document.createElement("span");
        if (zs === null || zs === undefined) {
          extra.className = "none";
          extra.textContent = "zeros: –";
          extra.title = (j.zero_errors && j.zero_errors[ch]) || "";
          td.dataset.rhp = "";
        } else {
          const rhp = zs.filter(isRhp);
          td.dataset.rhp = rhp.map((z) => String(z.re)).join(";");
          if (rhp.length) {
            extra.className = "rhp";
            extra.textContent = `RHP zero ${rhp.map(cplx).join(", ")}`;
          }
        }
        td.append(extra);
        tr.append(td);
      });
      return tr;
    }));
  }

  // ---------------------------------------------------------------------------------------------
  // step panel

  // a step's size when its input is chosen: the target the point's value of that input plus
  // this, or minus it where plus would leave the input's range (the slider's); it kept the
  // previous input's target (u_vgt's 65 % became a step of n_e from 1500 to 65 rpm, clamped)
  const STEP_SIZE = { u_vgt: -10, u_egr: -10, u_delta: 10, n_e: 100 };
  function stepTargetForInput() {
    const n = $("select[name=step_input]").value;
    const from = Number($(`input[name=${n}]`).value);
    const sl = $(`input[data-slider=${n}]`);
    if ($(`input[name=${n}]`).value.trim() === "" || !Number.isFinite(from)) return;
    let to = from + STEP_SIZE[n];
    if (to < Number(sl.min) || to > Number(sl.max)) to = from - STEP_SIZE[n];
    $("input[name=step_target]").value = String(Number(to.toPrecision(12)));
  }

  async function runStep() {
    await busy("[data-action=step]", "running step…", "#step-error", async () => {
      const body = { point: point(), input: $("select[name=step_input]").value, target: num("step_target", "step to"),
        horizon: num("step_horizon", "horizon"), ...modelSel() };
      const key = pointStamp();
      const at = pointText();
      const j = await api("/api/step", body);
      CHECK.step(j);
      app.step = j;
      stamp("step", key, `step of ${j.input} from ${tickLabel(j.from)} to ${tickLabel(j.to)} ${at}`);
      drawStep(j);
      // the server's warnings: a steady state not physically valid, an input the model clamps
      const w = j.warnings || [];
      $("#step-warnings").textContent = w.length ? `warning: ${w.join("; ")}` : "";
      $("#step-warnings").dataset.count = String(w.length);
      $("[data-download=step]").disabled = false;
    }, "step");
  }

  function drawStep(j) {
    const c = $("[data-plot=step]");
    const ctx = clearCanvas(c);
    const names = Object.keys(j.series);
    // the stepped input as the model applies it (clamped into its range), and the value asked
    // for dashed where it differs
    const applied = j.u_applied || j.u;
    const clamped = j.to_applied !== undefined && j.to_applied !== j.to;
    const inputTitle = `${j.input} [${j.input_unit}]` + (clamped ? `   applied ${tickLabel(j.to_applied)} (dashed: ${tickLabel(j.to)} asked, clamped)` : "");
    const panels = [{ name: inputTitle, y: applied, asked: clamped ? j.u : null, input: true }].concat(names.map((n) => ({ name: n, y: j.series[n], m: j.outputs[n] })));
    const cols = 2, rows = Math.ceil(panels.length / cols);
    const w = c.drawW / cols, h = c.drawH / rows;
    const xr = [j.t[0], j.t[j.t.length - 1]];
    let marks = { nmp: 0, overshoot: 0, dc: 0 };
    const yTicks = [];
    panels.forEach((pn, k) => {
      const box = [(k % cols) * w, Math.floor(k / cols) * h, w, h];
      let lo = Math.min(...pn.y), hi = Math.max(...pn.y);
      if (pn.asked) { lo = Math.min(lo, ...pn.asked); hi = Math.max(hi, ...pn.asked); }
      const m = pn.m;
      if (m && !m.error) { lo = Math.min(lo, m.y0, m.y_final); hi = Math.max(hi, m.y0, m.y_final); }
      const title = pn.input ? pn.name : `${pn.name} [${unit(pn.name)}]` + (m && !m.error ? `   DC gain ${fmt(m.dc_gain)} ${ratioUnit(unit(pn.name), j.input_unit)}` : "");
      const p = panel(ctx, box, xr, niceRange(lo, hi), title);
      yTicks.push(p.yTicks);
      if (m && !m.error) {
        line(ctx, p, xr, [m.y0, m.y0], "#9aa3b2", 1, [3, 3]);
        line(ctx, p, xr, [m.y_final, m.y_final], "#2e7d32", 1, [6, 3]);
        marks.dc++;
      }
      if (pn.asked) line(ctx, p, j.t, pn.asked, "#9aa3b2", 1, [4, 3]);
      line(ctx, p, j.t, pn.y, pn.input ? "#546e7a" : COLORS[k % COLORS.length]);
      if (m && !m.error) {
        // the labels clear of the lines of the steady values and of the curve
        const place = { clip: p.clip, lines: [p.py(m.y0), p.py(m.y_final)], taken: [],
          curve: j.t.flatMap((t, i) => Number.isFinite(pn.y[i]) ? [[p.px(t), p.py(pn.y[i])]] : []) };
        if (m.wrong_way && m.non_minimum_phase) {
          marker(ctx, p.px(m.wrong_way.time), p.py(m.wrong_way.value), "#c62828", `NMP ${(100 * m.wrong_way.relative).toFixed(1)} %`, "dot", place);
          marks.nmp++;
        }
        if (m.peak && m.overshoot_pct > 0.05) {
          marker(ctx, p.px(m.peak.time), p.py(m.peak.value), "#e67e22", `overshoot ${m.overshoot_pct.toFixed(1)} %`, "tri", place);
          marks.overshoot++;
        }
      }
    });
    c.dataset.series = String(panels.length);
    c.dataset.marks = JSON.stringify(marks);
    // the number of labelled y ticks of each panel
    c.dataset.yTicks = yTicks.join(",");
    c.dataset.drawn = String(Date.now());
    const tb = $("#metrics");
    tb.replaceChildren(...names.map((n) => {
      const m = j.outputs[n];
      const tr = document.createElement("tr");
      tr.dataset.metric = n;
      if (m.error) {
        // the server's message as text, never as markup
        const name = document.createElement("td");
        name.textContent = n;
        const msg = document.createElement("td");
        msg.colSpan = 6;
        msg.className = "msg";
        msg.textContent = String(m.error);
        tr.append(name, msg);
        return tr;
      }
      tr.innerHTML = `<td>${n} [${unit(n)}]</td><td data-field="dc_gain">${fmt(m.dc_gain)}</td><td>${m.gain_sign}</td>` +
        `<td data-field="nmp">${m.non_minimum_phase ? (100 * m.wrong_way.relative).toFixed(2) + " % at " + m.wrong_way.time.toFixed(3) + " s" : "–"}</td>` +
        `<td data-field="overshoot">${m.overshoot_pct.toFixed(2)} %</td><td>${m.rise_time === null ? "–" : m.rise_time.toFixed(3) + " s"}</td>` +
        `<td>${m.settling_time === null ? "–" : m.settling_time.toFixed(3) + " s"}</td>`;
      return tr;
    }));
  }

  // ---------------------------------------------------------------------------------------------
  // map panel

  async function runMap() {
    await busy("[data-action=map]", "computing map…", "#map-error", async () => {
      const n = Math.round(num("map_n", "points"));
      const body = {
        base: point(),
        x: { input: $("select[name=map_x]").value, lo: num("map_x_lo", "x from"), hi: num("map_x_hi", "x to"), n },
        y: { input: $("select[name=map_y]").value, lo: num("map_y_lo", "y from"), hi: num("map_y_hi", "y to"), n },
        channel: { input: $("select[name=map_input]").value, output: $("select[name=map_output]").value },
        ...modelSel(),
      };
      const t0 = performance.now();
      const key = pointStamp();
      const at = pointText();
      const j = await api("/api/map", body);
      CHECK.map(j);
      app.map = j;
      stamp("map", key, `around the point ${at}`);
      drawMap(j);
      $("#map-info").textContent = `${j.dc_gain.length} points in ${((performance.now() - t0) / 1000).toFixed(2)} s; ` +
        `${j.sign.filter((s) => s === 1).length} positive, ${j.sign.filter((s) => s === -1).length} negative, ${j.sign.filter((s) => s === 0).length} zero, ${j.errors.length} without a gain`;
      $("[data-download=map]").disabled = false;
    }, "map");
  }

  function drawMap(j) {
    const c = $("[data-plot=map]");
    const ctx = clearCanvas(c);
    const xs = j.x.values, ys = j.y.values, nx = xs.length, ny = ys.length;
    const legend = [["#5b8def", "positive"], ["#e4575f", "negative"], ["#f2d675", "zero"], ["#b9cdf7", "positive, not physically valid"], ["#f3b7ba", "negative, not physically valid"], ["#c9ced8", "no gain (kink / no equilibrium)"]];
    // the legend's items in rows that fit the canvas's width (at 1024 px the last item of the
    // second row ran past the edge, "no gain (kink"); the cells leave room for its rows
    ctx.font = "11px system-ui, sans-serif";
    const L = 60, R = 16, T = 28;
    const rows = [[]];
    let rowW = 0;
    legend.forEach(([col, lab], k) => {
      const itemW = 14 + ctx.measureText(lab).width;
      // (the signs on the first row, the not physically valid ones from the second on)
      if (rows.at(-1).length && (k === 3 || rowW + 16 + itemW > c.drawW - 8 - L)) { rows.push([]); rowW = 0; }
      rowW += (rows.at(-1).length ? 16 : 0) + itemW;
      rows.at(-1).push([col, lab]);
    });
    const B = 40 + 14 * rows.length;
    const w = (c.drawW - L - R) / nx, h = (c.drawH - T - B) / ny;
    for (let i = 0; i < nx; i++) {
      for (let k = 0; k < ny; k++) {
        const idx = i * ny + k;
        const s = j.sign[idx];
        ctx.fillStyle = s === 1 ? "#5b8def" : s === -1 ? "#e4575f" : s === 0 ? "#f2d675" : "#c9ced8";
        if (!j.physically_valid[idx] && s !== null) ctx.fillStyle = s === 1 ? "#b9cdf7" : "#f3b7ba";
        ctx.fillRect(L + i * w, T + (ny - 1 - k) * h, Math.ceil(w), Math.ceil(h));
      }
    }
    ctx.strokeStyle = "#8a93a3"; ctx.strokeRect(L, T, nx * w, ny * h);
    ctx.fillStyle = "#1d2330"; ctx.font = "12px system-ui, sans-serif"; ctx.textAlign = "left"; ctx.textBaseline = "top";
    ctx.fillText(`sign of the DC gain ${j.channel.input} → ${j.channel.output}`, L, 6);
    ctx.fillStyle = "#5d6778"; ctx.font = "11px system-ui, sans-serif";
    ctx.textAlign = "center";
    for (const v of ticks(xs[0], xs[nx - 1], 5)) ctx.fillText(tickLabel(v), L + (v - xs[0]) / (xs[nx - 1] - xs[0]) * (nx - 1) * w + w / 2, T + ny * h + 4);
    ctx.fillText(`${j.x.input} [${j.x.unit}]`, L + nx * w / 2, T + ny * h + 20);
    ctx.textAlign = "right"; ctx.textBaseline = "middle";
    for (const v of ticks(ys[0], ys[ny - 1], 5)) ctx.fillText(tickLabel(v), L - 4, T + (ny - 1 - (v - ys[0]) / (ys[ny - 1] - ys[0]) * (ny - 1)) * h + h / 2);
    ctx.save(); ctx.translate(14, T + ny * h / 2); ctx.rotate(-Math.PI / 2); ctx.textAlign = "center"; ctx.fillText(`${j.y.input} [${j.y.unit}]`, 0, 0); ctx.restore();
    ctx.textAlign = "left"; ctx.textBaseline = "top";
    rows.forEach((row, r) => {
      let x = L;
      const y = T + ny * h + 36 + 14 * r;
      for (const [col, lab] of row) {
        ctx.fillStyle = col; ctx.fillRect(x, y, 10, 10);
        ctx.fillStyle = "#5d6778"; ctx.fillText(lab, x + 14, y);
        x += ctx.measureText(lab).width + 30;
      }
    });
    c.dataset.cells = String(nx * ny);
    c.dataset.legendRows = String(rows.length);
  }

  // ---------------------------------------------------------------------------------------------
  // drive-cycle panel

  // the strips of the cycle figure: per strip its series and their colours (a reference
  // dashed, in the colour of what it is the reference of; a series the run lacks, as the
  // references in open loop, left out), and an upper display limit where spikes would flatten
  // the rest (lambda_O is 100+ while no fuel is injected)
  const REF = [5, 3];
  const CYCLE_PANELS = [
    { series: [["n_e", "#546e7a"]] },
    { series: [["u_delta", "#6d4c41"]] },
    { series: [["u_egr", "#2e7d32"], ["u_vgt", "#8e44ad"]] },
    { series: [["M_e", COLORS[0]], ["M_ref", "#1d2330", REF]] },
    { series: [["p_im", COLORS[0]], ["p_em", COLORS[1]]] },
    { series: [["W_c", "#00897b"]] },
    { series: [["x_egr", "#e67e22"], ["x_egr_ref", "#1d2330", REF]] },
    { series: [["lambda_O", COLORS[0]], ["lambda_O_ref", "#1d2330", REF]], cap: 8 },
  ];

  // a strip's legend in place of its title: per series a line sample in its colour and dash,
  // its name and unit
  function legend(ctx, p, y, items, note) {
    ctx.save();
    ctx.font = "12px system-ui, sans-serif"; ctx.textBaseline = "top"; ctx.textAlign = "left";
    let x = p.clip[0] + 4;
    for (const [name, color, dash] of items) {
      ctx.strokeStyle = color; ctx.lineWidth = 2; ctx.setLineDash(dash || []);
      ctx.beginPath(); ctx.moveTo(x, y + 8); ctx.lineTo(x + 18, y + 8); ctx.stroke();
      const text = `${name} [${unit(name)}]`;
      ctx.fillStyle = "#1d2330"; ctx.fillText(text, x + 22, y + 2);
      x += 22 + ctx.measureText(text).width + 14;
    }
    if (note) { ctx.fillStyle = "#5d6778"; ctx.fillText(note, x, y + 2); }
    ctx.restore();
  }
  let cycleImage = null;

  // closed loop with "loop margins every" ticked: its seconds (the server checks the range and
  // names "margins"); undefined otherwise
  const marginsOn = () => $("select[name=cycle_mode]").value === "closed" && $("input[name=cycle_margins]").checked;
  function marginsEvery() {
    if (!marginsOn()) return undefined;
    const s = $("input[name=cycle_margins_every]").value.trim();
    const v = s === "" ? NaN : Number(s);
    if (!Number.isFinite(v)) throw new Error(`loop margins every: "${s}" is not a number of seconds`);
    return v;
  }

  async function runCycle() {
    await busy("[data-action=cycle]", marginsOn() ? "simulating the cycle and its loop margins…" : "simulating the cycle…", "#cycle-error", async () => {
      const t0 = performance.now();
      const cycle = $("select[name=cycle]").value;
      // (fit_dt: a cycle of several hours is sampled coarser than 0.2 s, with a note, instead
      // of refused for a dt the page has no field for)
      const body = { mode: $("select[name=cycle_mode]").value, dt: 0.2, fit_dt: true, ...modelSel() };
      if (cycle === FILE_CYCLE) body.csv = app.cycleFile.text; else body.cycle = cycle;
      if (body.mode === "closed" && app.tuningDefaults) body.tuning = tuningValue();
      body.margins = marginsEvery();
      const key = cycleStamp(body.mode);
      const source = cycle === FILE_CYCLE ? `file ${app.cycleFile.name}` : cycle === "whtc" ? "the WHTC" : cycle;
      const at = `${source}, ${MODE_LABELS[body.mode] || body.mode}, ${body.model} states, parameters ${$("select[name=params]").value}`;
      let j;
      try {
        j = await api("/api/simulate", body);
      } catch (e) {
        // the server's time limit (60 s) reached with the loop margins along the run: say what
        // makes it shorter (on a loaded 2-core machine every 2 s of the WHTC took longer)
        if (e.status === 503 && body.margins !== undefined) {
          e.message += `; the loop margins every ${body.margins} s cost about 40 ms of CPU per sample: a larger spacing runs faster`;
        }
        throw e;
      }
      CHECK.simulate(j);
      app.cycle = j;
      app.cycleFromFile = cycle === FILE_CYCLE;
      stamp("cycle", key, at);
      showCycleStats(j);
      Object.assign(app.units, j.units || {});
      drawCycle(j);
      showCycleMargins(j);
      let info = `${j.t.length} samples, ${j.stats.steps} solver steps, ${((performance.now() - t0) / 1000).toFixed(2)} s`;
      if (j.mode === "closed") {
        // the regulation's cycle validation of the run (mvem closed-loop's stats.json)
        info += j.passes ? "; regulation check: passes" : `; regulation check fails: ${(j.violations || []).join("; ")}`;
      }
      // open loop: inputs the model clamped into the parameter set's ranges
      if ((j.warnings || []).length) info += `; warning: ${j.warnings.join("; ")}`;
      $("#cycle-info").textContent = info;
      const sl = $("input[name=cycle_t]");
      sl.max = String(j.t.length - 1); sl.value = "0"; sl.disabled = false;
      // the time of a link: the sample nearest to it
      if (app.urlCycleT !== undefined) {
        const t = app.urlCycleT;
        app.urlCycleT = undefined;
        if (t < j.t[0] || t > j.t[j.t.length - 1]) addUrlProblem("cycle_t", `${t} s is outside the run's ${j.t[0]} to ${j.t[j.t.length - 1]} s`);
        else sl.value = String(j.t.reduce((b, x, i) => Math.abs(x - t) < Math.abs(j.t[b] - t) ? i : b, 0));
      }
      scrub();
      $("[data-download=cycle]").disabled = false;
    }, "cycle");
  }

  // ---------------------------------------------------------------------------------------------
  // controller tuning of the closed-loop mode (fields, units and defaults from /api/models)

  const TUNING_KEY = /^(\w+)\[(\d)\]$/; // "torque[2]": ki of the torque PI (1-based, as the server's messages)

  function buildTuning(t) {
    app.tuningDefaults = t.defaults;
    app.tuningBounds = {};
    $("#tuning-fields").replaceChildren(...t.fields.map((f) => {
      const d = t.defaults[f.name];
      const keys = Array.isArray(d) ? [[`${f.name}[1]`, "kp"], [`${f.name}[2]`, "ki"]] : [[f.name, ""]];
      const inputs = document.createElement("td");
      inputs.className = "i";
      for (const [key, lab] of keys) {
        if (lab) { const l = document.createElement("span"); l.className = "unit"; l.textContent = ` ${lab} `; inputs.append(l); }
        const inp = document.createElement("input");
        inp.type = "number"; inp.step = "any"; inp.dataset.tuning = key;
        // (read out as "torque kp", not "torque[1]")
        inp.setAttribute("aria-label", lab ? `${f.name} ${lab}` : f.name);
        // the accepted interval (BaselineTuning::BOUNDS): the browser marks a value outside it
        // (min/max include their ends; an open end is checked in boundsMessage)
        if (f.bounds) {
          inp.min = String(f.bounds.lo); inp.max = String(f.bounds.hi); inp.title = `accepted: ${f.bounds.interval}`;
          app.tuningBounds[key] = f.bounds;
        }
        inputs.append(inp);
      }
      const name = cell("", f.name);
      name.title = f.description;
      const tr = document.createElement("tr");
      tr.append(name, inputs, cell("unit", f.unit), cell("unit iv", f.bounds ? f.bounds.interval : ""), cell("d", f.description));
      return tr;
    }));
    resetTuning();
  }

  function tuningDefault(key) {
    const m = TUNING_KEY.exec(key);
    return m ? app.tuningDefaults[m[1]][Number(m[2]) - 1] : app.tuningDefaults[key];
  }

  function resetTuning() {
    for (const inp of $$("input[data-tuning]")) inp.value = String(tuningDefault(inp.dataset.tuning));
    markTuning();
  }

  // "" when the entry lies in its accepted interval, else why not (the open ends, which the
  // input's min/max cannot express, included); set as the input's custom validity
  function boundsMessage(key, text) {
    const b = app.tuningBounds[key];
    const v = text.trim() === "" ? NaN : Number(text);
    if (!b || !Number.isFinite(v)) return "";
    const below = b.lo_open ? v <= b.lo : v < b.lo;
    const above = b.hi_open ? v >= b.hi : v > b.hi;
    return below || above ? `${key} = ${v}: must lie in ${b.interval}` : "";
  }

  // highlight the entries that differ from the defaults, and those outside their interval
  function markTuning() {
    let changed = 0;
    for (const inp of $$("input[data-tuning]")) {
      inp.setCustomValidity(boundsMessage(inp.dataset.tuning, inp.value));
      const on = inp.value.trim() === "" || Number(inp.value) !== tuningDefault(inp.dataset.tuning);
      inp.classList.toggle("changed", on);
      changed += on ? 1 : 0;
    }
    $("#tuning-changed").textContent = changed ? `${changed} changed from the defaults` : "the defaults";
    // the loop margins and a closed-loop run shown were computed with the tuning before
    markStale();
    scheduleUrl();
  }

  // the request's "tuning" from the form; an entry that is not a number is an error naming it
  // (the server checks the ranges: BaselineTuning::validate)
  function tuningValue() {
    const t = {};
    for (const inp of $$("input[data-tuning]")) {
      const key = inp.dataset.tuning;
      const v = inp.value.trim() === "" ? NaN : Number(inp.value);
      if (!Number.isFinite(v)) throw new Error(`controller tuning ${key}: "${inp.value}" is not a number`);
      const m = TUNING_KEY.exec(key);
      if (m) {
        if (!t[m[1]]) t[m[1]] = [...app.tuningDefaults[m[1]]];
        t[m[1]][Number(m[2]) - 1] = v;
      } else {
        t[key] = v;
      }
    }
    return t;
  }

  // the tuning form in closed-loop mode, and the file format the mode reads
  function showCycleMode() {
    const closed = $("select[name=cycle_mode]").value === "closed";
    $("#tuning").hidden = !closed;
    $("#cycle-margins-control").hidden = !closed;
    // what a file of the cycle menu must hold in this mode (the server names what is wrong)
    $("#cycle-format").textContent = closed
      ? "closed loop: the WHTC, or a file of a speed/torque demand with the columns t [s], n_e [rpm], M_ref [Nm], or a normalized cycle with the columns Time [s], Speed [%], Torque [%] (\"m\": motoring; as mvem closed-loop --cycle FILE)"
      : "open loop: the WHTC, or a file of inputs with the columns time_s, n_e_rpm, u_delta_mg, u_egr_pct, u_vgt_pct (as mvem simulate --inputs)";
  }

  // a user's cycle file: read once, then one more entry of the cycle menu
  const FILE_CYCLE = "__file";
  async function loadCycleFile() {
    const inp = $("input[name=cycle_file]");
    const f = inp.files[0];
    if (!f) return;
    try {
      app.cycleFile = { name: f.name, text: await f.text() };
    } finally {
      // emptied: choosing the same file again (edited since) is a change that reads it again
      inp.value = "";
    }
    const sel = $("select[name=cycle]");
    let opt = sel.querySelector(`option[value="${FILE_CYCLE}"]`);
    if (!opt) { opt = new Option("", FILE_CYCLE); sel.append(opt); }
    opt.textContent = `file: ${f.name}`;
    sel.value = FILE_CYCLE;
    showError("#cycle-error", null);
  }

  // the closed-loop run's cycle statistics (mvem closed-loop's stats.json) and the tuning it used
  function showCycleStats(j) {
    const tbl = $("#cycle-stats");
    const s = j.cycle_stats;
    if (j.mode !== "closed" || !s) { tbl.hidden = true; return; }
    // a figure that does not apply to the run is null (NaN in the core), with the reason in
    // not_applicable ("work_error: ..."; a regression's in its own): said so, not drawn as a
    // number (a constant speed demand's speed regression failed as "Cannot read properties of
    // null (reading 'toFixed')")
    const why = (key) => (s.not_applicable || []).find((r) => r.startsWith(`${key}:`));
    const na = (key) => { const r = why(key); return `not applicable${r ? ` (${r.slice(key.length + 1).trim()})` : ""}`; };
    const fix = (v, d, key) => v === null ? na(key) : v.toFixed(d);
    const pct = (v, key) => v === null ? na(key) : `${(100 * v).toFixed(2)} %`;
    const reg = (r, u) => r.slope === null || r.r2 === null || r.see === null
      ? `not applicable${r.not_applicable ? ` (${r.not_applicable})` : ""}`
      : `slope ${r.slope.toFixed(3)}, R² ${r.r2.toFixed(3)}, SEE ${r.see.toFixed(1)} ${u}`;
    const changed = Object.entries(j.controller_tuning || {})
      .filter(([k, v]) => k !== "ts" && JSON.stringify(v) !== JSON.stringify(app.tuningDefaults?.[k]))
      .map(([k, v]) => `${k} = ${JSON.stringify(v)}`);
    const rows = [
      ["controller tuning", changed.length ? changed.join(", ") : "the defaults"],
      ["positive work, actual / reference", `${fix(s.work_act_kwh, 3, "work_act_kwh")} / ${fix(s.work_ref_kwh, 3, "work_ref_kwh")} kWh (${s.work_error >= 0 ? "+" : ""}${pct(s.work_error, "work_error")})`],
      ["torque regression", reg(s.torque, "Nm")],
      ["power regression", reg(s.power, "kW")],
      ["speed regression", reg(s.speed, "rpm")],
      ["lambda_O min (fired)", s.lambda_o_min === null ? na("lambda_o_min") : `${s.lambda_o_min.toFixed(3)} at t = ${fix(s.lambda_o_min_t, 2, "lambda_o_min_t")} s`],
      [`lambda_O below ${s.lambda_limit}`, s.lambda_below_limit_share === null ? na("lambda_below_limit_share") : `${pct(s.lambda_below_limit_share)} of fired samples`],
      ["x_egr RMS error", fix(s.x_egr_rms_error, 4, "x_egr_rms_error")],
      ["mean p_em − p_im", s.pmep_mean_pa === null ? na("pmep_mean_pa") : `${(s.pmep_mean_pa / 1000).toFixed(2)} kPa`],
      ["fuel, BSFC", `${fix(s.fuel_kg, 3, "fuel_kg")} kg, ${s.bsfc_g_kwh === null ? `BSFC ${na("bsfc_g_kwh")}` : `${s.bsfc_g_kwh.toFixed(1)} g/kWh`}`],
    ];
    $("tbody", tbl).replaceChildren(...rows.map(([k, v]) => {
      const tr = document.createElement("tr");
      tr.append(cell("", k), cell("", v));
      return tr;
    }));
    tbl.hidden = false;
  }

  // an input as the model applied it (the authors' saturation clamps a command outside its
  // range: the server's "inputs_applied"), a series as computed
  function cycleValue(j, n, i) {
    return (j.series[n] ?? (j.inputs_applied || j.inputs)[n])[i];
  }

  // the commanded values of input `n` where the model applied another one (clamped), else null
  function cycleCommanded(j, n) {
    const c = j.inputs[n], a = j.inputs_applied?.[n];
    return a && c && c.some((v, i) => v !== a[i]) ? c : null;
  }

  function drawCycle(j) {
    const c = $("[data-plot=cycle]");
    const ctx = clearCanvas(c);
    const h = c.drawH / CYCLE_PANELS.length;
    const xr = [j.t[0], j.t[j.t.length - 1]];
    const drawn = [];
    app.cyclePanels = CYCLE_PANELS.map(({ series, cap }, k) => {
      const items = series.filter(([n]) => (j.series[n] ?? j.inputs[n]) !== undefined);
      const ys = items.map(([n]) => j.series[n] ?? (j.inputs_applied || j.inputs)[n]);
      // an input the model clamped somewhere: its commanded values dashed in grey under the
      // applied ones
      const asked = items.map(([n]) => j.series[n] ? null : cycleCommanded(j, n));
      let [lo, hi] = robustRange(ys.concat(asked.filter((a) => a)), 0.002);
      const capped = cap !== undefined && hi > cap;
      if (capped) hi = cap;
      const p = panel(ctx, [0, k * h, c.drawW, h], xr, niceRange(lo, hi), "",
        { xLabel: k === CYCLE_PANELS.length - 1 ? "t [s]" : undefined });
      asked.forEach((a) => { if (a) line(ctx, p, j.t, a, "#9aa3b2", 1, [4, 3]); });
      // (a reference dashed over what follows it)
      items.forEach(([, color, dash], q) => line(ctx, p, j.t, ys[q], color, dash ? 1.2 : 1, dash || []));
      const notes = [];
      if (asked.some((a) => a)) notes.push("(grey dashed: commanded, clamped to the range)");
      if (capped) notes.push(`(axis cut at ${cap})`);
      legend(ctx, p, k * h, items, notes.join(" "));
      drawn.push(...items.map(([n]) => n));
      return p;
    });
    cycleImage = snapshot(c);
    c.dataset.yTicks = app.cyclePanels.map((p) => p.yTicks).join(",");
    c.dataset.series = drawn.join(",");
    c.dataset.drawn = String(j.t.length);
  }

  // ---------------------------------------------------------------------------------------------
  // loop margins along a closed-loop run (POST /api/simulate "margins": the summary and the
  // samples of mvem::control::along, as mvem closed-loop --margins S): per loop while it was in
  // feedback, its gain margin [dB] and phase margin [deg] with the other loop closed, on the
  // cycle plot's time axis (as mvem closed-loop --margins S --plot draws margins.svg); a red
  // band at each sample whose loops are unstable together

  // the loops' colours: not the red of the unstable bands
  const LOOP_COLORS = [COLORS[0], COLORS[2], COLORS[3], COLORS[4], COLORS[5], COLORS[6]];
  const UNSTABLE_FILL = "rgba(198,40,40,0.22)";
  let marginsImage = null;
  // a time of the run as the page shows it (the samples lie on the 10 ms controller grid)
  const tText = (t) => String(Number(t.toFixed(3)));

  function showCycleMargins(j) {
    const m = j.margins;
    $("#cycle-margins").hidden = !m;
    marginsImage = null;
    if (!m) return;
    const s = m.summary;
    const unstable = s.unstable_t;
    const shown = unstable.slice(0, 20).map(tText).join(", ") + (unstable.length > 20 ? ", …" : "");
    const el = $("#cycle-margins-summary");
    el.textContent = `every ${s.every_s} s: ${s.points} samples, ${s.analysed} analysed (${s.invalid_steady} at a physically invalid steady state), ` +
      `${s.no_loop} without a loop in feedback, ${s.refused} refused; ` +
      (unstable.length ? `loops UNSTABLE together at ${unstable.length} samples: t = ${shown} s` : "every analysed sample's loops stable together");
    el.title = unstable.map(tText).join(", ");
    Object.assign(el.dataset, { points: s.points, analysed: s.analysed, noLoop: s.no_loop, refused: s.refused, unstable: unstable.length, stable: String(!unstable.length) });
    // an extreme and its time: two cells
    const at = (x, text) => x === null ? [cell("", "–"), cell("", "")] : [cell("", text(x.value)), cell("t", tText(x.t))];
    $("#cycle-margins-loops tbody").replaceChildren(...s.loops.map((l, k) => {
      const tr = document.createElement("tr");
      tr.dataset.loop = l.name;
      tr.dataset.minGainMargin = l.min_gain_margin === null ? "" : String(l.min_gain_margin.value);
      const name = cell("", `● ${l.name.replace("->", " → ")}`);
      name.style.color = LOOP_COLORS[k % LOOP_COLORS.length];
      const unstable = cell(l.unstable ? "bad" : "", String(l.unstable));
      tr.append(name, cell("", String(l.points)), unstable, cell("", String(l.inert)),
        ...at(l.min_gain_margin, (v) => `${v.toPrecision(4)} (${(20 * Math.log10(v)).toFixed(2)} dB)`),
        ...at(l.min_phase_margin_deg, (v) => v.toFixed(1)),
        ...at(l.max_peak_sensitivity, (v) => v.toPrecision(4)));
      return tr;
    }));
    drawCycleMargins(j);
  }

  function drawCycleMargins(j) {
    const m = j.margins;
    const c = $("[data-plot=cycle-margins]");
    const ctx = clearCanvas(c);
    const xr = [j.t[0], j.t[j.t.length - 1]];
    const names = m.summary.loops.map((l) => l.name);
    // per loop: [t, gain margin dB] and [t, phase margin deg], with the other loop closed
    const pts = names.map(() => ({ gm: [[], []], pm: [[], []] }));
    for (const p of m.samples) {
      for (const l of p.loops || []) {
        const q = pts[names.indexOf(l.name)];
        if (!q) continue;
        const oc = l.others_closed;
        if (oc.gain_margin !== null) { q.gm[0].push(p.t); q.gm[1].push(20 * Math.log10(oc.gain_margin)); }
        if (oc.phase_margin_deg !== null) { q.pm[0].push(p.t); q.pm[1].push(oc.phase_margin_deg); }
      }
    }
    const strips = [["gm", "gain margin [dB], other loop closed (0 dB: the stability boundary)"], ["pm", "phase margin [deg], other loop closed"]];
    const h = c.drawH / strips.length;
    let dots = 0;
    app.marginsPanels = [];
    strips.forEach(([key, title], k) => {
      const [lo, hi] = robustRange(pts.map((q) => q[key][1]), 0);
      const p = panel(ctx, [0, k * h, c.drawW, h], xr, niceRange(Math.min(lo, 0), Math.max(hi, 0)), title,
        { yTicks: 5, xLabel: k === strips.length - 1 ? "t [s]" : undefined });
      app.marginsPanels.push(p);
      // the samples whose loops are unstable together: a band as wide as the spacing (at least
      // 3 px), over the whole height of the strip
      ctx.save(); ctx.beginPath(); ctx.rect(...p.clip); ctx.clip();
      ctx.fillStyle = UNSTABLE_FILL;
      for (const t of m.summary.unstable_t) {
        const a = p.px(t - m.summary.every_s / 2), b = p.px(t + m.summary.every_s / 2);
        const w = Math.max(3, b - a);
        ctx.fillRect((a + b - w) / 2, p.clip[1], w, p.clip[3]);
      }
      ctx.restore();
      line(ctx, p, xr, [0, 0], "#9aa3b2", 1, [4, 3]);
      pts.forEach((q, i) => {
        const [ts, ys] = q[key];
        ctx.save(); ctx.beginPath(); ctx.rect(...p.clip); ctx.clip();
        ctx.fillStyle = LOOP_COLORS[i % LOOP_COLORS.length];
        for (let n = 0; n < ts.length; n++) {
          ctx.beginPath(); ctx.arc(p.px(ts[n]), p.py(ys[n]), 2.5, 0, 2 * Math.PI); ctx.fill();
        }
        ctx.restore();
        dots += ts.length;
      });
    });
    // the legend: under the figure, in the loops' colours
    const legend = $("#cycle-margins-legend");
    legend.replaceChildren(...names.map((n, i) => {
      const span = document.createElement("span");
      span.className = "key";
      span.style.color = LOOP_COLORS[i % LOOP_COLORS.length];
      span.textContent = `● ${n.replace("->", " → ")}`;
      return span;
    }));
    const band = document.createElement("span");
    band.className = "key unstable";
    band.textContent = "▮ loops in feedback unstable together";
    const note = document.createElement("div");
    note.textContent = "each sample analysed at the steady state of its commands (a frozen operating point), with the loops in feedback then; the fuel path is not in the analysis (docs/control.md)";
    legend.append(band, note);
    marginsImage = snapshot(c);
    c.dataset.dots = String(dots);
    c.dataset.bands = String(m.summary.unstable_t.length);
    c.dataset.drawn = String(m.samples.length);
  }

  function scrub() {
    const j = app.cycle;
    if (!j) return;
    const i = Number($("input[name=cycle_t]").value);
    const c = $("[data-plot=cycle]");
    const ctx = cycleImage ? restore(c, cycleImage) : c.getContext("2d");
    const X = app.cyclePanels[0].px(j.t[i]);
    // the cursor over each strip's plot area only: across the whole canvas it ran through the
    // time axis's tick labels and hid the "0" at the start under a red bar
    const cursor = (cx, panels) => {
      cx.save(); cx.strokeStyle = "rgba(198,40,40,0.8)"; cx.beginPath();
      for (const p of panels) { const [, y, , hh] = p.clip; cx.moveTo(X, y); cx.lineTo(X, y + hh); }
      cx.stroke(); cx.restore();
    };
    cursor(ctx, app.cyclePanels);
    // the margins figure shares the time axis
    if (j.margins && marginsImage) {
      const mc = $("[data-plot=cycle-margins]");
      cursor(restore(mc, marginsImage), app.marginsPanels || []);
    }
    $("#cycle-time").textContent = j.t[i].toFixed(1);
    const names = INPUTS.concat(Object.keys(j.series));
    $("#cycle-values").replaceChildren(...names.map((n) => {
      const tr = document.createElement("tr");
      // an input: the value the model applied; where the command was outside the input's range
      // (clamped), the command beside it
      const v = cycleValue(j, n, i);
      const cmd = j.series[n] === undefined ? j.inputs[n][i] : v;
      const note = document.createElement("td");
      note.className = "d";
      if (cmd !== v) {
        note.textContent = `commanded ${fmt(cmd)}, clamped to the range`;
        note.dataset.commanded = String(cmd);
      }
      tr.innerHTML = `<td>${n}</td><td class="v" data-cycle-signal="${n}">${fmt(v)}</td><td class="u">${unit(n)}</td>`;
      tr.append(note);
      return tr;
    }));
  }

  // ---------------------------------------------------------------------------------------------
  // CSV downloads (of what is shown)

  // a CSV column's header: the name and its unit in brackets, `p_im [Pa]`, `x_egr [-]` (the
  // units of /api/models, those of mvem's JSON and figures); the form in which mvem reads a
  // unit from a header (mvem closed-loop --cycle FILE, a campaign's files:
  // csv_columns::split_unit), so the closed-loop cycle's CSV is a demand file mvem closed-loop
  // reads (t [s], n_e [rpm], M_ref [Nm]; the other columns ignored). mvem simulate --out writes
  // the bare names in SI units (n_e, n_t in rpm, u_delta in mg/cycle, u_* in %; README)
  const csvHead = (name, u = unit(name)) => u ? `${name} [${u}]` : name;

  function downloads() {
    $("[data-download=steady]").addEventListener("click", () => {
      const j = app.steady;
      if (!j) return;
      // (the inputs n_e ... u_vgt are signals of the answer: the values the model applied)
      const rows = [["name", "value", "unit"]];
      for (const [k, v] of Object.entries(j)) if (typeof v === "number") rows.push([k, v, unit(k)]);
      rows.push(["physically_valid", j.physically_valid, ""], ["flags", (j.flags || []).join(";"), ""]);
      download("steady.csv", rows);
    });
    $("[data-download=step]").addEventListener("click", () => {
      const j = app.step;
      if (!j) return;
      const names = Object.keys(j.series);
      // the stepped input as commanded and, where the model clamped it (the parameter set's
      // input ranges), beside it the values it applied, as the cycle's CSV has them
      const clamped = j.u_applied && j.u.some((v, i) => v !== j.u_applied[i]);
      const applied = clamped ? [csvHead(`${j.input}_applied`, j.input_unit)] : [];
      const rows = [[csvHead("t", "s"), csvHead(j.input, j.input_unit), ...applied, ...names.map((n) => csvHead(n))]];
      j.t.forEach((t, i) => rows.push([t, j.u[i], ...(clamped ? [j.u_applied[i]] : []), ...names.map((n) => j.series[n][i])]));
      download(`step_${j.input}.csv`, rows);
    });
    $("[data-download=map]").addEventListener("click", () => {
      const j = app.map;
      if (!j) return;
      const gain = csvHead(`dc_gain_${j.channel.input}_${j.channel.output}`, ratioUnit(unit(j.channel.output), unit(j.channel.input)));
      const rows = [[csvHead(j.x.input, j.x.unit), csvHead(j.y.input, j.y.unit), gain, "sign", "physically_valid"]];
      const ny = j.y.values.length;
      j.dc_gain.forEach((g, idx) => rows.push([j.x.values[Math.floor(idx / ny)], j.y.values[idx % ny], g, j.sign[idx], j.physically_valid[idx]]));
      download("map.csv", rows);
    });
    $("[data-download=linear]").addEventListener("click", () => {
      const j = app.linear;
      if (!j) return;
      saveFile("linear_model.json", JSON.stringify(j, null, 1) + "\n", "application/json");
    });
    $("[data-download=cycle]").addEventListener("click", () => {
      const j = app.cycle;
      if (!j) return;
      const names = Object.keys(j.series);
      // the commands as given, and beside each one the model clamped somewhere (the
      // parameter set's input ranges) the values it applied
      const applied = INPUTS.filter((n) => cycleCommanded(j, n));
      // (the run's units, those of /api/models)
      const u = (n) => (j.units || {})[n] ?? unit(n);
      const rows = [[csvHead("t", "s"), ...INPUTS.map((n) => csvHead(n, u(n))), ...applied.map((n) => csvHead(`${n}_applied`, u(n))), ...names.map((n) => csvHead(n, u(n)))]];
      j.t.forEach((t, i) => rows.push([
        t,
        ...INPUTS.map((n) => j.inputs[n][i]),
        ...applied.map((n) => j.inputs_applied[n][i]),
        ...names.map((n) => j.series[n][i]),
      ]));
      download(`${j.source}_${j.mode}.csv`, rows);
    });
  }

  // the figures drawn again at their new size when the window's size (or its pixel ratio:
  // the zoom) changes
  let resizeTimer = 0;
  function redrawAll() {
    if (app.step) drawStep(app.step);
    if (app.linear) drawBode();
    if (app.map) drawMap(app.map);
    if (app.cycle) {
      drawCycle(app.cycle);
      if (app.cycle.margins && !$("#cycle-margins").hidden) drawCycleMargins(app.cycle);
      scrub();
    }
  }

  // ---------------------------------------------------------------------------------------------
  // the page's state in its link: the model, parameter set, operating point, every panel's
  // settings, the controller tuning entries that differ from the defaults, which panels show a
  // result and the cycle's time (`#model=8&params=published&n_e=1500&...&show=step,linear`),
  // written with history.replaceState as they change (no history entry per move), read when
  // the page loads (and when the hash is edited): a link or bookmark opens the same view, the
  // panels it lists computed again at its point. A value the page would not take (not a
  // number, outside its field's range, not an entry of its menu, an unknown name) is ignored,
  // the field keeps its default, and the note under the header names it (#url-note)

  // the fields of the link: its name, the control, and whether it is always written (the
  // operating point, model and parameter set; the others only where they differ from the
  // page's defaults)
  const URL_FIELDS = [
    ["model", "select[name=model]", true], ["params", "select[name=params]", true],
    ...INPUTS.map((n) => [n, `input[name=${n}]`, true]),
    ["step_input", "select[name=step_input]"], ["step_target", "input[name=step_target]"], ["step_horizon", "input[name=step_horizon]"],
    ["lin_ts", "input[name=lin_ts]"], ["bode_fmin", "input[name=bode_fmin]"], ["bode_fmax", "input[name=bode_fmax]"],
    ["map_input", "select[name=map_input]"], ["map_output", "select[name=map_output]"],
    ["map_x", "select[name=map_x]"], ["map_x_lo", "input[name=map_x_lo]"], ["map_x_hi", "input[name=map_x_hi]"],
    ["map_y", "select[name=map_y]"], ["map_y_lo", "input[name=map_y_lo]"], ["map_y_hi", "input[name=map_y_hi]"], ["map_n", "input[name=map_n]"],
    ["cycle_mode", "select[name=cycle_mode]"], ["cycle_margins", "input[name=cycle_margins]"],
    ["cycle_margins_every", "input[name=cycle_margins_every]"],
  ].map(([name, sel, always]) => ({ name, sel, always: !!always }));
  // the panels whose result the link asks for again
  const URL_PANELS = ["step", "linear", "margins", "map", "cycle"];
  const RUNS = { step: () => runStep(), linear: () => runLinearize(), margins: () => runMargins(), map: () => runMap(), cycle: () => runCycle() };
  // a tuning entry's name in the link: "tuning.egr_lambda.kp" for the PI pair's "egr_lambda[1]"
  const tuningParam = (key) => { const m = TUNING_KEY.exec(key); return `tuning.${m ? `${m[1]}.${m[2] === "1" ? "kp" : "ki"}` : key}`; };

  // a control's value as the link writes it (undefined: nothing to write, as a field without
  // a number or the cycle menu's file, which a link cannot carry)
  function readField(el) {
    if (el.type === "checkbox") return el.checked ? "1" : "0";
    const v = el.value.trim();
    // (a blank field: nothing, but the optional sample time, whose blank is its default "none")
    if (el.tagName === "INPUT" && (v === "" ? el.name !== "lin_ts" : !Number.isFinite(Number(v)))) return undefined;
    return v;
  }
  // why the text `v` is no value of the control `el` ("" when it is one)
  function fieldProblem(el, v) {
    if (el.tagName === "SELECT") {
      const opts = [...el.options].map((o) => o.value).filter((o) => o !== FILE_CYCLE);
      return opts.includes(v) ? "" : `not one of ${opts.join(", ")}`;
    }
    if (el.type === "checkbox") return v === "1" || v === "0" ? "" : "not 1 or 0";
    // (an optional field, the sample time, may be empty: none)
    if (v.trim() === "" && el.name === "lin_ts") return "";
    const x = v.trim() === "" ? NaN : Number(v);
    if (!Number.isFinite(x)) return "not a number";
    const lo = el.min === "" ? -Infinity : Number(el.min), hi = el.max === "" ? Infinity : Number(el.max);
    if (x < lo || x > hi) return hi === Infinity ? `below its least value ${el.min}` : lo === -Infinity ? `above its largest value ${el.max}` : `outside [${el.min}, ${el.max}]`;
    if (el.step === "1" && !Number.isInteger(x)) return "not a whole number";
    return "";
  }
  // the text of a value in a note: quoted, at most 40 characters
  const quoted = (v) => JSON.stringify(v.length > 40 ? `${v.slice(0, 40)}…` : v);

  // the page's defaults, taken once /api/models has filled the menus (before a link is read)
  let urlDefaults = null;
  function takeUrlDefaults() {
    urlDefaults = Object.fromEntries(URL_FIELDS.map((f) => [f.name, readField($(f.sel))]));
  }

  // the state as the link's parameters ([name, value] in order)
  function urlState() {
    const out = [];
    for (const f of URL_FIELDS) {
      const el = $(f.sel);
      const v = readField(el);
      if (v === undefined) continue;
      if (f.always || v !== urlDefaults[f.name]) out.push([f.name, v]);
    }
    const cycle = $("select[name=cycle]").value;
    if (cycle !== FILE_CYCLE && cycle !== "whtc") out.push(["cycle", cycle]);
    for (const inp of app.tuningDefaults ? $$("input[data-tuning]") : []) {
      const v = readField(inp);
      if (v !== undefined && v !== "" && Number(v) !== tuningDefault(inp.dataset.tuning)) out.push([tuningParam(inp.dataset.tuning), v]);
    }
    // (what a link asked for and its panel has not computed yet kept as the link had it)
    const ch = app.urlBode ?? $("select[name=bode_channel]").value;
    if ((app.linear || app.urlBode !== undefined) && ch && ch !== "u_vgt->W_c") out.push(["bode_channel", ch]);
    // the panels with a result (a cycle run of a file: not, a link cannot carry the file)
    const shown = URL_PANELS.filter((p) => (stamps[p] && !(p === "cycle" && app.cycleFromFile)) || app.urlPending.has(p));
    if (shown.length) out.push(["show", shown.join(",")]);
    const i = Number($("input[name=cycle_t]").value);
    if (app.urlCycleT !== undefined) out.push(["cycle_t", String(app.urlCycleT)]);
    else if (app.cycle && !app.cycleFromFile && i > 0) out.push(["cycle_t", String(app.cycle.t[i])]);
    return out;
  }
  const urlText = (state) => state.map(([k, v]) => `${encodeURIComponent(k)}=${encodeURIComponent(v).replace(/%2C/g, ",")}`).join("&");

  // the link written at most every 100 ms (a slider's drag moves many times a second; Chromium
  // throttles replaceState called too often)
  let urlTimer = 0;
  function scheduleUrl() {
    if (!urlDefaults || app.applyingUrl) return;
    clearTimeout(urlTimer);
    urlTimer = setTimeout(writeUrl, 100);
  }
  function writeUrl() {
    clearTimeout(urlTimer);
    if (!urlDefaults) return;
    const hash = `#${urlText(urlState())}`;
    if (hash !== location.hash) history.replaceState(history.state, "", `${location.pathname}${location.search}${hash}`);
    document.body.dataset.url = hash;
  }

  // the note naming what the link held that the page did not take
  function showUrlNote(problems) {
    app.urlProblems = problems;
    const el = $("#url-note");
    el.dataset.ignored = problems.map(([name]) => name).join(",");
    el.textContent = problems.length ? `the link's ${problems.map(([name, text]) => `${name}: ${text}`).join("; ")}: ignored (the page's value kept)` : "";
    el.hidden = !problems.length;
  }

  // one more thing of the link ignored (found once its panel has computed)
  const addUrlProblem = (name, text) => showUrlNote([...(app.urlProblems || []), [name, text]]);

  // the state of the link (`hash`, without "#") set into the page; returns the panels it shows
  function applyUrl(hash) {
    const q = new URLSearchParams(hash);
    const problems = [];
    const given = new Map();
    for (const [k, v] of q) {
      if (given.has(k)) { if (!problems.some(([n]) => n === k)) problems.push([k, "given twice"]); given.set(k, null); continue; }
      given.set(k, v);
    }
    const value = (name) => given.get(name);
    app.applyingUrl = true;
    try {
      const fields = Object.fromEntries(URL_FIELDS.map((f) => [f.name, f]));
      // what the link does not give is the page's default (a hash edited in the address bar
      // after other changes sets the view of that link, not a mix)
      for (const f of URL_FIELDS) {
        const el = $(f.sel);
        if (el.type === "checkbox") el.checked = urlDefaults[f.name] === "1";
        else if (urlDefaults[f.name] !== undefined) el.value = urlDefaults[f.name];
      }
      if ($("select[name=cycle]").value !== FILE_CYCLE) $("select[name=cycle]").selectedIndex = 0;
      for (const inp of app.tuningDefaults ? $$("input[data-tuning]") : []) inp.value = String(tuningDefault(inp.dataset.tuning));
      applyInputRanges();
      const set = (name) => {
        const v = value(name);
        if (v === undefined || v === null) return false;
        const el = $(fields[name].sel);
        const why = fieldProblem(el, v);
        if (why) { problems.push([name, `${quoted(v)} is ${why}`]); return false; }
        if (el.type === "checkbox") el.checked = v === "1"; else el.value = v;
        return true;
      };
      // the menus first: the parameter set (the sliders' ranges and the map axes follow it as
      // when it is chosen), then the inputs whose choice sets another field (the step's target,
      // a map axis's range) unless the link gives that field too
      const params = $("select[name=params]").value;
      set("params");
      set("model");
      if ($("select[name=params]").value !== params) {
        applyInputRanges();
        for (const a of ["x", "y"]) if (RANGED_INPUTS.includes($(`select[name=map_${a}]`).value)) applyMapRange(a);
      }
      for (const f of URL_FIELDS) if (!["params", "model"].includes(f.name) && f.sel.startsWith("select")) set(f.name);
      if (value("map_x") !== undefined) applyMapRange("x");
      if (value("map_y") !== undefined) applyMapRange("y");
      for (const f of URL_FIELDS) if (!f.sel.startsWith("select")) set(f.name);
      if (value("step_input") !== undefined && value("step_target") === undefined) stepTargetForInput();
      applyInputRanges();
      if (given.has("cycle")) {
        const v = given.get("cycle");
        const opts = [...$("select[name=cycle]").options].map((o) => o.value).filter((o) => o !== FILE_CYCLE);
        if (v !== null && opts.includes(v)) $("select[name=cycle]").value = v; else if (v !== null) problems.push(["cycle", `${quoted(v)} is not one of ${opts.join(", ")}`]);
      }
      // the controller tuning: a known entry within its accepted interval
      const keys = Object.fromEntries($$("input[data-tuning]").map((inp) => [tuningParam(inp.dataset.tuning), inp]));
      for (const [k, v] of given) {
        if (!k.startsWith("tuning.") || v === null) continue;
        const inp = keys[k];
        const x = v.trim() === "" ? NaN : Number(v);
        if (!inp) problems.push([k, "not an entry of the controller tuning"]);
        else if (!Number.isFinite(x)) problems.push([k, `${quoted(v)} is not a number`]);
        else if (boundsMessage(inp.dataset.tuning, v)) problems.push([k, `${quoted(v)} is outside ${app.tuningBounds[inp.dataset.tuning].interval}`]);
        else inp.value = v;
      }
      // the view: the Bode channel (once the linear model is there), the cycle's time (once
      // the cycle has run), the panels to compute
      app.urlBode = value("bode_channel") ?? undefined;
      const t = value("cycle_t");
      app.urlCycleT = undefined;
      if (t !== undefined && t !== null) {
        if (!Number.isFinite(Number(t)) || t.trim() === "") problems.push(["cycle_t", `${quoted(t)} is not a number`]);
        else app.urlCycleT = Number(t);
      }
      const show = [];
      for (const p of (value("show") ?? "").split(",").filter((p) => p)) {
        if (URL_PANELS.includes(p)) { if (!show.includes(p)) show.push(p); } else problems.push(["show", `${quoted(p)} is not one of ${URL_PANELS.join(", ")}`]);
      }
      if (app.urlCycleT !== undefined && !show.includes("cycle")) { problems.push(["cycle_t", "without a cycle to show"]); app.urlCycleT = undefined; }
      if (app.urlBode !== undefined && !show.includes("linear")) { problems.push(["bode_channel", "without the linear model to show"]); app.urlBode = undefined; }
      const known = new Set([...URL_FIELDS.map((f) => f.name), "cycle", "bode_channel", "cycle_t", "show"]);
      for (const k of given.keys()) if (!known.has(k) && !k.startsWith("tuning.")) problems.push([k, "no setting of the page"]);
      showUrlNote(problems);
      showCycleMode();
      markTuning();
      return show;
    } finally {
      app.applyingUrl = false;
    }
  }

  // "Copy link": the link to the clipboard, or, where the browser does not allow that (a page
  // not served from 127.0.0.1 or https), shown selected to copy by hand
  async function copyLink() {
    writeUrl();
    const out = $("#link-copied");
    const box = $("input[name=link]");
    try {
      await navigator.clipboard.writeText(location.href);
      box.hidden = true;
      out.textContent = "link copied";
    } catch (e) {
      box.value = location.href;
      box.hidden = false;
      box.select();
      out.textContent = "copy the link from the field";
    }
    out.dataset.href = location.href;
  }

  // ---------------------------------------------------------------------------------------------
  // start

  async function init() {
    wireInputs();
    downloads();
    $("[data-action=step]").addEventListener("click", runStep);
    $("select[name=step_input]").addEventListener("change", stepTargetForInput);
    $("[data-action=linearize]").addEventListener("click", runLinearize);
    $("[data-action=map]").addEventListener("click", runMap);
    $("[data-action=cycle]").addEventListener("click", runCycle);
    $("input[name=cycle_t]").addEventListener("input", scrub);
    $("select[name=cycle_mode]").addEventListener("change", showCycleMode);
    $("select[name=bode_channel]").addEventListener("change", drawBode);
    $("[data-action=margins]").addEventListener("click", runMargins);
    $("input[name=cycle_file]").addEventListener("change", () => loadCycleFile().catch((e) => showError("#cycle-error", e)));
    $("[data-action=tuning-defaults]").addEventListener("click", resetTuning);
    window.addEventListener("resize", () => { clearTimeout(resizeTimer); resizeTimer = setTimeout(redrawAll, 100); });
    $("#tuning-fields").addEventListener("input", markTuning);
    try {
      const m = await api("/api/models");
      CHECK.models(m);
      app.units = m.units || {};
      $("select[name=params]").replaceChildren(...m.params.map((p) => new Option(p, p)));
      app.inputRanges = m.input_ranges || {};
      applyInputRanges();
      if (m.cycles.length) $("select[name=cycle]").replaceChildren(...m.cycles.map((cy) => new Option(cy === "whtc" ? "WHTC (built in)" : cy, cy)));
      $("select[name=cycle_mode]").replaceChildren(...m.modes.map((md) => new Option(MODE_LABELS[md] || md, md)));
      if (m.controller_tuning) buildTuning(m.controller_tuning);
      showCycleMode();
      refreshStatus();
    } catch (e) {
      // (the answer's error names /api/models; an HTTP error or no answer is named here; no
      // answer's message already says "server unreachable", so it is not prefixed "server: ")
      app.modelsError = e.kind === "network" ? `/api/models: ${e.message}`
        : `server: ${e.kind === "answer" ? "" : "/api/models: "}${e.message}`;
      refreshStatus();
    }
    buildSignalTable();
    // the link's state (the defaults taken first: the link holds what differs from them), the
    // link written as the controls change, read again when the hash is edited
    takeUrlDefaults();
    const fromLink = () => {
      const show = applyUrl(location.hash.slice(1));
      app.urlPending = new Set(show);
      scheduleSteady();
      for (const p of show) RUNS[p]();
      writeUrl();
    };
    if (location.hash.length > 1) fromLink(); else requestSteady();
    window.addEventListener("hashchange", fromLink);
    for (const ev of ["input", "change"]) document.addEventListener(ev, scheduleUrl, true);
    $("[data-action=copy-link]").addEventListener("click", copyLink);
  }

  init();
})();
