// Live status of the flight page: polls the session-authenticated JSON route (the session cookie goes with the
// same-origin request; no token in this script) while a file is incomplete or a job queued/running, updates
// the cells, and reloads once everything has settled so that new results and figures appear.
(function () {
  "use strict";
  var me = document.currentScript;
  var url = me.getAttribute("data-status");
  var PERIOD_MS = 1500;

  function active(s) {
    return s.files.some(function (f) { return f.status !== "complete"; }) ||
      s.jobs.some(function (j) { return j.status === "queued" || j.status === "running"; });
  }

  function text(el, value) { if (el && el.textContent !== value) { el.textContent = value; } }

  function update(s) {
    var state = document.getElementById("state");
    text(state, s.state);
    if (state) { state.className = "state " + s.state; }
    var known = {};
    document.querySelectorAll("#job-table tr[data-job]").forEach(function (tr) { known[tr.dataset.job] = tr; });
    var reload = false;
    s.jobs.forEach(function (j) {
      var tr = known[j.id];
      if (!tr) { reload = true; return; }
      var badge = tr.querySelector(".job-status span");
      if (badge.textContent !== j.status) {
        badge.textContent = j.status;
        badge.className = "state " + j.status;
        if (j.status === "done" || j.status === "failed") { reload = true; }
      }
      text(tr.querySelector(".job-message"), j.message);
    });
    s.files.forEach(function (f) {
      var tr = document.querySelector('#file-table tr[data-file="' + CSS.escape(f.name) + '"]');
      if (!tr) { reload = true; return; }
      var bar = tr.querySelector("progress");
      if (bar) { bar.value = f.size ? f.received : 1; }
      text(tr.querySelector(".file-received span"), f.received + " B");
      if (tr.querySelector(".file-status").textContent !== f.status) {
        text(tr.querySelector(".file-status"), f.status);
        if (f.status === "complete") { reload = true; }
      }
    });
    return reload;
  }

  function poll() {
    fetch(url, { credentials: "same-origin", headers: { "Accept": "application/json" } })
      .then(function (r) {
        if (r.status === 401) { window.location.reload(); throw new Error("signed out"); }
        if (!r.ok) { throw new Error("HTTP " + r.status); }
        return r.json();
      })
      .then(function (s) {
        var reload = update(s);
        if (reload && !active(s)) { window.location.reload(); return; }
        if (active(s) || reload) { window.setTimeout(poll, PERIOD_MS); }
      })
      .catch(function () { window.setTimeout(poll, PERIOD_MS * 4); });
  }

  poll();
}());
