// The experimenter's dashboard: a login form, then the figures the server sent (see studyapp/web/dashboard.py).
"use strict";
(function () {
  var root = document.getElementById("app");
  var S = JSON.parse(document.getElementById("state").textContent);
  function el(tag, text, attrs) {
    var e = document.createElement(tag);
    if (text !== undefined && text !== null) e.textContent = String(text);
    Object.keys(attrs || {}).forEach(function (k) { e.setAttribute(k, attrs[k]); });
    return e;
  }
  function post(url, body) {
    return fetch(url, {method: "POST", credentials: "same-origin", headers: {"Content-Type": "application/json"},
      body: JSON.stringify(body || {})}).then(function (r) { return r.json().then(function (d) { return {ok: r.ok, data: d}; }); });
  }
  root.appendChild(el("h1", "Dashboard: " + S.title));
  var error = el("p", "", {id: "error", role: "alert", "class": "error"});
  if (S.screen === "login") {
    var form = el("form", null, {id: "login"});
    var pw = el("input", null, {type: "password", id: "password", autocomplete: "current-password"});
    form.appendChild(el("label", "Password "));
    form.appendChild(pw);
    form.appendChild(el("button", "Log in", {type: "submit", "class": "primary"}));
    form.addEventListener("submit", function (ev) {
      ev.preventDefault();
      post("/dashboard/login", {password: pw.value}).then(function (r) {
        if (r.ok) window.location.assign(r.data.go); else error.textContent = r.data.error || "error";
      });
    });
    root.appendChild(form);
    root.appendChild(error);
    return;
  }
  var t = S.totals;
  var facts = [["Participants", S.participants], ["Completed", t.done], ["In progress", t.active],
    ["Ended by attention checks", t.attention], ["Abandoned (row given out again)", t.abandoned], ["Declined consent", t.declined],
    ["Failed attention checks (all participants)", S.failed_attention_checks],
    ["Median minutes to complete", S.median_minutes_to_complete === null ? "-" : S.median_minutes_to_complete],
    ["Median seconds per trial (shown to answered)", S.median_seconds_per_trial === null ? "-" : S.median_seconds_per_trial]];
  var dl = el("table", null, {id: "totals"});
  facts.forEach(function (f) { var tr = el("tr"); tr.appendChild(el("th", f[0])); tr.appendChild(el("td", f[1])); dl.appendChild(tr); });
  root.appendChild(dl);
  root.appendChild(el("h2", "Progress per Latin-square row"));
  var table = el("table", null, {id: "rows"});
  var head = el("tr");
  ["Row", "Completed", "In progress", "Attention", "Abandoned", "Declined"].forEach(function (h) { head.appendChild(el("th", h)); });
  table.appendChild(head);
  S.rows.forEach(function (r) {
    var tr = el("tr");
    [r.row, r.done, r.active, r.attention, r.abandoned, r.declined].forEach(function (v) { tr.appendChild(el("td", v)); });
    table.appendChild(tr);
  });
  root.appendChild(table);
  var bar = el("p", null, {"class": "buttons"});
  var a = el("a", "Export results (CSV)", {href: "/dashboard/export.csv", id: "export", download: "results.csv"});
  bar.appendChild(a);
  var out = el("button", "Log out", {type: "button", id: "logout"});
  out.addEventListener("click", function () { post("/dashboard/logout").then(function () { window.location.assign("/dashboard"); }); });
  bar.appendChild(out);
  root.appendChild(bar);
  root.appendChild(error);
})();
