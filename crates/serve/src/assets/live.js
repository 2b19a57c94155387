// errmap serve, live page: show each snapshot the server pushes on /api/live (Server-Sent
// Events). Text goes in through textContent only, never as HTML.
"use strict";
(function () {
  const $ = (id) => document.getElementById(id);
  const csrfField = document.querySelector("#controls input[name=csrf]");
  const csrf = csrfField ? csrfField.value : null;

  function cell(row, text, cls) {
    const td = document.createElement("td");
    td.textContent = text === null || text === undefined ? "—" : String(text);
    if (cls) td.className = cls;
    row.appendChild(td);
    return td;
  }
  function num(v, digits) {
    return v === null || v === undefined ? null : Number(v).toFixed(digits);
  }
  function fill(id, items, columns) {
    const body = $(id).querySelector("tbody");
    body.replaceChildren();
    for (const item of items) {
      const row = document.createElement("tr");
      for (const col of columns) col(row, item);
      body.appendChild(row);
    }
  }
  function ackForm(row, alarm) {
    const td = document.createElement("td");
    if (csrf && !alarm.acknowledged) {
      const form = document.createElement("form");
      form.method = "post";
      form.action = "/live/command";
      for (const [name, value] of [["csrf", csrf], ["command", "ack"], ["alarm_id", String(alarm.id)]]) {
        const input = document.createElement("input");
        input.type = "hidden";
        input.name = name;
        input.value = value;
        form.appendChild(input);
      }
      const button = document.createElement("button");
      button.type = "submit";
      button.textContent = "Acknowledge";
      form.appendChild(button);
      td.appendChild(form);
    }
    row.appendChild(td);
  }

  function show(snapshot) {
    const s = snapshot.state;
    $("problem").textContent = snapshot.problem || (snapshot.stale ? "the live state is stale: errmap live has not rewritten it for 3 periods" : "");
    $("problem").hidden = !(snapshot.problem || snapshot.stale);
    document.body.classList.toggle("stale", !!snapshot.stale);
    if (!s) {
      $("mode").textContent = "no state";
      return;
    }
    $("mode").textContent = s.mode;
    $("mode").className = "mode-" + s.mode;
    $("cycle").textContent = String(s.cycle);
    $("written").textContent = s.written_utc;
    $("period").textContent = s.period_ms + " ms";
    $("dry-run").textContent = s.dry_run ? "yes (nothing is written to the controller)" : "no";
    $("coolant").textContent = s.coolant_on === null ? "unknown" : s.coolant_on ? "on" : "off";
    fill("sensors", s.sensors, [
      (r, x) => cell(r, x.name),
      (r, x) => cell(r, num(x.value_c, 2), "num"),
      (r, x) => cell(r, x.ok ? "ok" : "fault", x.ok ? "ok" : "bad"),
      (r, x) => cell(r, x.source),
      (r, x) => cell(r, x.age_ms, "num"),
      (r, x) => cell(r, x.problem),
    ]);
    fill("axes", s.axes, [
      (r, x) => cell(r, x.axis),
      (r, x) => cell(r, num(x.position_mm, 3), "num"),
      (r, x) => cell(r, x.direction),
      (r, x) => cell(r, num(x.computed_um, 2), "num"),
      (r, x) => cell(r, num(x.written_um, 2), "num"),
      (r, x) => cell(r, num(x.limit_um, 1), "num"),
      (r, x) => cell(r, num(x.rate_limit_um_s, 1), "num"),
      (r, x) => cell(r, x.target),
      (r, x) => cell(r, x.held ? "held" : "", x.held ? "bad" : ""),
    ]);
    fill("sources", s.sources, [
      (r, x) => cell(r, x.name),
      (r, x) => cell(r, x.kind),
      (r, x) => cell(r, x.healthy ? "healthy" : "unhealthy", x.healthy ? "ok" : "bad"),
      (r, x) => cell(r, x.last_ok_utc),
      (r, x) => cell(r, x.problem),
    ]);
    fill("alarms", s.alarms, [
      (r, x) => cell(r, x.id, "num"),
      (r, x) => cell(r, x.raised_utc),
      (r, x) => cell(r, x.source),
      (r, x) => cell(r, x.message),
      (r, x) => cell(r, x.acknowledged ? "acknowledged" : "open", x.acknowledged ? "" : "bad"),
      ackForm,
    ]);
  }

  const source = new EventSource("/api/live");
  source.addEventListener("state", (e) => show(JSON.parse(e.data)));
  source.addEventListener("error", () => {
    $("connection").textContent = "reconnecting…";
  });
  source.addEventListener("open", () => {
    $("connection").textContent = "connected";
  });
})();
