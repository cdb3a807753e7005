// studyapp's browser participant page: draws the state the server sends and posts the participant's actions.
// The server decides everything (what comes next, whether a clip was watched, whether an answer is valid);
// this script only shows it. Ranking: drag a figure's label into a box, click labels in order, or press the
// figure's number key (it goes into the next free box); Up/Down change question, Backspace clears one,
// Enter goes on. Preference (pairwise, mismatch): click an answer or press its number, Left/Right move it.
// Preference reasons: Down past the last question reaches them, their number keys tick them.
// Rating: one slider per figure and question, each must be moved; Up/Down choose a slider, number keys jump.
"use strict";
(function () {
  var root = document.getElementById("app");
  var S = JSON.parse(document.getElementById("state").textContent);
  var busy = false;

  function el(tag, attrs) {
    var e = document.createElement(tag);
    var a = attrs || {};
    Object.keys(a).forEach(function (k) {
      if (k === "text") e.textContent = a[k];
      else if (k === "on") Object.keys(a.on).forEach(function (ev) { e.addEventListener(ev, a.on[ev]); });
      else e.setAttribute(k, a[k]);
    });
    for (var i = 2; i < arguments.length; i++) if (arguments[i]) e.appendChild(arguments[i]);
    return e;
  }
  function paragraphs(text) {
    var box = el("div", {"class": "text"});
    String(text || "").split(/\n\s*\n/).forEach(function (p) { if (p.trim()) box.appendChild(el("p", {text: p.trim()})); });
    return box;
  }
  function showError(msg) {
    var e = document.getElementById("error");
    if (e) e.textContent = msg || "";
  }
  function request(url, body) {
    return fetch(url, {method: "POST", credentials: "same-origin", cache: "no-store",
      headers: {"Content-Type": "application/json", "X-CSRF-Token": S.csrf || ""},
      body: JSON.stringify(body || {})}).then(function (r) {
      return r.json().then(function (data) { return {ok: r.ok, data: data}; });
    });
  }
  // post an action; on success the reply is the next state. onState(next) may keep the page (trials).
  function post(action, body, onState) {
    if (busy) return Promise.resolve(null);
    busy = true;
    showError("");
    return request(S.base + action, body).then(function (res) {
      busy = false;
      if (!res.ok) {
        if (res.data.refused) { S = {screen: "refused", heading: S.title, text: res.data.refused}; render(); }
        else showError(res.data.error || "error");
        return null;
      }
      var before = S.screen;
      S = res.data;
      if (onState && before === S.screen && onState(S) === true) return S;
      render();
      return S;
    }, function () { busy = false; showError("No connection to the server; please try again."); return null; });
  }
  function button(id, label, onClick, cls) {
    return el("button", {id: id, type: "button", "class": cls || "primary", text: label, on: {click: onClick}});
  }
  function shell(heading) {
    root.textContent = "";
    document.onkeydown = null;
    root.appendChild(el("h1", {text: heading || S.title || ""}));
    var body = el("div", {"class": "page"});
    root.appendChild(body);
    root.appendChild(el("div", {id: "error", role: "alert", "class": "error"}));
    return body;
  }
  function onEnter(fn) {
    document.onkeydown = function (ev) { if (ev.key === "Enter" && ev.target.tagName !== "TEXTAREA") { ev.preventDefault(); fn(); } };
  }

  // ------------------------------------------------------------------ fixed pages
  function welcome() {
    var b = shell(S.heading);
    b.appendChild(paragraphs(S.consent));
    b.appendChild(el("p", {"class": "note", text: S.note}));
    function start(consent) {
      if (busy) return;
      busy = true;
      request("/start", {nonce: S.nonce, csrf: S.entry_csrf, consent: consent, params: S.params}).then(function (res) {
        busy = false;
        if (res.ok) window.location.assign(res.data.go);
        else if (res.data.refused) { S = {screen: "refused", heading: S.title, text: res.data.refused}; render(); }
        else showError(res.data.error || "error");
      });
    }
    var ask = el("div", {"class": "ask hidden"}, el("p", {text: S.decline_ask}),
      button("decline-confirm", S.decline_confirm, function () { start(false); }, "secondary"),
      button("decline-back", S.decline_back, function () { ask.classList.add("hidden"); }, "secondary"));
    b.appendChild(el("div", {"class": "buttons"}, button("agree", S.agree, function () { start(true); }),
      button("decline", S.decline, function () { ask.classList.remove("hidden"); }, "secondary")));
    b.appendChild(ask);
    onEnter(function () { start(true); });
  }
  function back() {
    var b = shell(S.heading);
    S.lines.forEach(function (l) { b.appendChild(el("p", {text: l})); });
    b.appendChild(button("continue", S.button, function () { post("continue"); }));
    onEnter(function () { post("continue"); });
  }
  function block() {
    var b = shell(S.heading);
    b.appendChild(paragraphs(S.text));
    b.appendChild(button("continue", S.button, function () { post("block"); }));
    onEnter(function () { post("block"); });
  }
  function instructions() {
    var b = shell(S.heading);
    b.appendChild(paragraphs(S.text));
    b.appendChild(el("h2", {text: S.questions_title}));
    var list = el("dl");
    S.criteria.forEach(function (c) {
      list.appendChild(el("dt", {text: c.label + ": " + c.question}));
      if (c.explanation) list.appendChild(el("dd", {text: c.explanation}));
    });
    b.appendChild(list);
    b.appendChild(el("h2", {text: S.how_title}));
    b.appendChild(paragraphs(S.how));
    if (S.ties) b.appendChild(paragraphs(S.ties));
    b.appendChild(button("continue", S.button, function () { post("continue"); }));
    onEnter(function () { post("continue"); });
  }
  function soundcheck() {
    var b = shell(S.heading);
    b.appendChild(paragraphs(S.text));
    var tone = new Audio(S.tone);
    function heard() {
      post("sound", {user_agent: navigator.userAgent, screen_w: window.screen.width, screen_h: window.screen.height});
    }
    b.appendChild(el("div", {"class": "buttons"},
      button("tone", S.play, function () { tone.currentTime = 0; tone.play().catch(function () {}); }, "secondary"),
      button("heard", S.button, heard)));
    document.onkeydown = function (ev) {
      if (ev.key === "t" || ev.key === "T") { tone.currentTime = 0; tone.play().catch(function () {}); }
      if (ev.key === "Enter") heard();
    };
  }
  function final() {
    var b = shell(S.heading);
    b.appendChild(paragraphs(S.text));
    if (S.code) b.appendChild(el("p", {id: "code", "class": "code", text: S.code}));
    if (S.redirect) {
      b.appendChild(button("return", S.button, function () { window.location.assign(S.redirect); }));
      window.setTimeout(function () { window.location.assign(S.redirect); }, 2500);
    }
  }

  // ------------------------------------------------------------------ a trial
  // The page around the video is the same for every paradigm; the answer panel is the paradigm's:
  // rankPanel (rank), preferencePanel (pairwise, mismatch), ratingPanel (rating). A panel draws itself into
  // its element and says which questions are still open, what to send, and which keys it takes.
  function trial() {
    var b = shell(S.progress);
    if (S.practice_note) b.appendChild(el("p", {"class": "note", text: S.practice_note}));
    var video = el("video", {id: "video", src: S.video, preload: "auto", playsinline: ""});
    var status = el("p", {id: "status", "class": "status"});
    var play = button("play", S.texts["trial.play"], startPlay, "secondary");
    b.appendChild(el("div", {"class": "stage"}, video));
    b.appendChild(el("div", {"class": "buttons"}, play, status));
    var box = el("div", {id: "panel", "class": "panel"});
    b.appendChild(box);
    var next = button("next", S.texts.next, submit);
    var hint = el("p", {id: "hint", "class": "note"});
    b.appendChild(el("div", {"class": "buttons"}, next, hint));
    var playing = false;
    var panel = (S.paradigm === "pairwise" || S.paradigm === "mismatch") ? preferencePanel(box, refresh) :
      (S.paradigm === "rating" ? ratingPanel(box, refresh) : rankPanel(box, refresh));

    function refresh() {
      var watched = S.can_rank;
      play.textContent = (watched || S.plays) ? S.texts["trial.replay"] : S.texts["trial.play"];
      play.disabled = playing || !S.can_play;
      status.textContent = playing ? S.texts["trial.watch"] :
        (watched ? (S.allow_replay ? S.texts["trial.rank_replay"] : S.texts["trial.rank_now"]) : S.texts["trial.ready"]);
      box.classList.toggle("locked", !watched);
      panel.draw();
      var missing = panel.missing();
      next.disabled = !watched || missing.length > 0 || playing;
      // nothing answered yet: how to answer (mouse and keys), as the desktop says it; then what is still open
      hint.textContent = !watched ? S.texts["rank.wait"] :
        (missing.length === panel.size ? S.texts.start_hint :
          (missing.length ? S.texts.still.replace("{criteria}", missing.join(", ")) : S.texts["rank.next_ok"]));
    }
    function startPlay() {
      if (playing || !S.can_play) return;
      post("play", {}, function (next) { S = next; return true; }).then(function (st) {
        if (!st) return;
        playing = true;
        S.plays = (S.plays || 0) + 1;
        video.currentTime = 0;
        var p = video.play();
        if (p && p.catch) p.catch(function (e) { playing = false; showError(String(e)); refresh(); });
        refresh();
      });
    }
    video.addEventListener("ended", function () {
      if (!playing) return;
      post("ended", {play: S.play}, function (next) { S = next; return true; }).then(function () { playing = false; refresh(); });
    });
    function submit() {
      if (next.disabled) return;
      post("answer", panel.answer());
    }
    document.onkeydown = function (ev) {
      if (ev.key === " " && ev.target.tagName !== "INPUT") {
        ev.preventDefault();
        if (playing) { if (video.paused) video.play(); else video.pause(); } else startPlay();
        return;
      }
      if (!S.can_rank) return;
      if (ev.key === "Enter") { ev.preventDefault(); submit(); return; }
      if (panel.key(ev)) ev.preventDefault();
    };
    refresh();
  }

  function rankPanel(panel, refresh) {
    var n = S.labels.length;
    var order = S.criteria.map(function () { return [null, null, null]; });   // per question: slot in each box
    var tied = S.criteria.map(function () { return [false, false]; });        // box i tied with box i+1
    var active = 0;
    function place(ci, slot, box) {
      if (!S.can_rank) return;
      var o = order[ci];
      var at = o.indexOf(slot);
      if (at >= 0) o[at] = null;
      if (box === undefined) box = o.indexOf(null);
      if (box < 0) return;
      o[box] = slot;
      active = ci;
      if (o.indexOf(null) < 0 && ci + 1 < S.criteria.length && order[ci + 1].indexOf(null) >= 0) active = ci + 1;
      refresh();
    }
    function ranksOf(ci) {   // rank of each slot: its box, or the first box of its tie group
      var r = {};
      for (var box = 0; box < 3; box++) {
        var first = box;
        while (first > 0 && tied[ci][first - 1]) first--;
        r[String(order[ci][box])] = first + 1;
      }
      return r;
    }
    // pointer dragging (mouse, pen, touch): a copy of the label follows the pointer; dropped on a box, it goes there
    function dragSource(chip, ci, slot) {
      chip.addEventListener("pointerdown", function (ev) {
        if (!S.can_rank) return;
        ev.preventDefault();
        var ghost = el("span", {"class": "chip ghost", text: S.labels[slot]});
        document.body.appendChild(ghost);
        var moved = false;
        function move(e) { moved = true; ghost.style.left = e.clientX + "px"; ghost.style.top = e.clientY + "px"; }
        function up(e) {
          document.removeEventListener("pointermove", move);
          document.removeEventListener("pointerup", up);
          ghost.remove();
          var target = document.elementFromPoint(e.clientX, e.clientY);
          var box = target && target.closest ? target.closest("[data-box]") : null;
          var row = box ? box.closest("[data-criterion]") : null;
          if (box && row && row.getAttribute("data-criterion") === S.criteria[ci].id) place(ci, slot, Number(box.getAttribute("data-box")));
          else if (!moved || !box) place(ci, slot);   // a click: the next free box
        }
        move(ev); moved = false;
        document.addEventListener("pointermove", move);
        document.addEventListener("pointerup", up);
      });
    }
    return {
      size: S.criteria.length,
      draw: function () {
        panel.textContent = "";
        S.criteria.forEach(function (c, ci) {
          var row = el("div", {"class": "criterion" + (ci === active ? " active" : ""), "data-criterion": c.id});
          row.appendChild(el("h3", {text: c.label + ": " + c.question}));
          var chips = el("div", {"class": "chips"});
          for (var s = 0; s < n; s++) {
            var chip = el("span", {"class": "chip" + (order[ci].indexOf(s) >= 0 ? " used" : ""), "data-slot": String(s),
              id: "chip-" + c.id + "-" + s, text: S.labels[s], tabindex: "-1"});
            dragSource(chip, ci, s);
            chips.appendChild(chip);
          }
          row.appendChild(chips);
          var boxes = el("div", {"class": "boxes"});
          var names = [S.texts["rank.first"], S.texts["rank.second"], S.texts["rank.third"]];
          for (var bx = 0; bx < 3; bx++) {
            var slot = order[ci][bx];
            var box = el("span", {"class": "box" + (slot === null ? "" : " filled"), "data-box": String(bx),
              id: "box-" + c.id + "-" + bx},
              el("small", {text: names[bx]}), el("strong", {text: slot === null ? S.texts["rank.drop_here"] : S.labels[slot]}));
            box.addEventListener("click", (function (i, b) { return function () {
              if (order[i][b] !== null) { order[i][b] = null; active = i; refresh(); } }; })(ci, bx));
            boxes.appendChild(box);
            if (bx < 2 && S.allow_ties) {
              var t = tied[ci][bx];
              boxes.appendChild(el("button", {type: "button", "class": "tie", id: "tie-" + c.id + "-" + bx,
                title: t ? S.texts["rank.tie_on"] : S.texts["rank.tie_off"], text: t ? "=" : ">",
                on: {click: (function (i, b) { return function () { tied[i][b] = !tied[i][b]; refresh(); }; })(ci, bx)}}));
            }
          }
          row.appendChild(boxes);
          panel.appendChild(row);
        });
      },
      missing: function () {
        return S.criteria.filter(function (c, i) { return order[i].indexOf(null) >= 0; }).map(function (c) { return c.label; });
      },
      answer: function () {
        var ranks = {};
        S.criteria.forEach(function (c, i) { ranks[c.id] = ranksOf(i); });
        return {ranks: ranks};
      },
      key: function (ev) {
        var k = Number(ev.key);
        if (k >= 1 && k <= n) { place(active, k - 1); return true; }
        if (ev.key === "ArrowDown") { active = Math.min(active + 1, S.criteria.length - 1); refresh(); return true; }
        if (ev.key === "ArrowUp") { active = Math.max(active - 1, 0); refresh(); return true; }
        if (ev.key === "Backspace") { order[active] = [null, null, null]; tied[active] = [false, false]; refresh(); return true; }
        return false;
      }
    };
  }

  function preferencePanel(panel, refresh) {
    var chosen = S.criteria.map(function () { return null; });   // per question: index into S.options
    var reasons = {};
    var active = 0;
    function choose(ci, k) {
      chosen[ci] = k;
      active = ci + 1 < S.criteria.length && chosen[ci + 1] === null ? ci + 1 : ci;
      refresh();
    }
    function preferring() {
      return chosen.some(function (k) { return k !== null && S.options[k].value !== 0; });
    }
    return {
      size: S.criteria.length,
      draw: function () {
        panel.textContent = "";
        S.criteria.forEach(function (c, ci) {
          var row = el("div", {"class": "criterion" + (ci === active ? " active" : ""), "data-criterion": c.id});
          row.appendChild(el("h3", {text: c.label + ": " + c.question}));
          var opts = el("div", {"class": "options"});
          S.options.forEach(function (o, k) {
            opts.appendChild(el("button", {type: "button", id: "opt-" + c.id + "-" + o.value,
              "class": "option" + (chosen[ci] === k ? " chosen" : ""), "aria-pressed": String(chosen[ci] === k),
              text: (k + 1) + ". " + o.text, on: {click: function () { choose(ci, k); }}}));
          });
          row.appendChild(opts);
          panel.appendChild(row);
        });
        if (S.reasons.length && preferring()) {
          var box = el("fieldset", {"class": "reasons" + (active === S.criteria.length ? " active" : "")},
            el("legend", {text: S.texts.reasons}));
          S.reasons.forEach(function (r, i) {
            var input = el("input", {type: "checkbox", id: "reason-" + i});
            input.checked = !!reasons[r];
            input.addEventListener("change", function () { reasons[r] = input.checked; });
            box.appendChild(el("label", {"class": "option"}, input, el("span", {text: (i + 1) + ". " + r})));
          });
          panel.appendChild(box);
        }
      },
      missing: function () {
        return S.criteria.filter(function (c, i) { return chosen[i] === null; }).map(function (c) { return c.label; });
      },
      answer: function () {
        var levels = {};
        S.criteria.forEach(function (c, i) { levels[c.id] = S.options[chosen[i]].value; });
        var why = preferring() ? S.reasons.filter(function (r) { return reasons[r]; }) : [];
        return {levels: levels, reasons: why};
      },
      key: function (ev) {
        var k = Number(ev.key);
        var last = S.criteria.length - 1 + (S.reasons.length && preferring() ? 1 : 0);   // the reasons: one row more
        if (active > last) active = last;
        if (active === S.criteria.length) {     // on the reasons: their number keys tick them
          if (k >= 1 && k <= S.reasons.length) { reasons[S.reasons[k - 1]] = !reasons[S.reasons[k - 1]]; refresh(); return true; }
          if (ev.key === "ArrowUp") { active -= 1; refresh(); return true; }
          if (ev.key === "Backspace") { reasons = {}; refresh(); return true; }
          return ev.key === "ArrowDown";
        }
        if (k >= 1 && k <= S.options.length) { choose(active, k - 1); return true; }
        if (ev.key === "ArrowLeft" || ev.key === "ArrowRight") {
          var at = chosen[active] === null ? (S.options.length - 1) / 2 : chosen[active];
          chosen[active] = Math.max(0, Math.min(S.options.length - 1, at + (ev.key === "ArrowLeft" ? -1 : 1)));
          refresh(); return true;
        }
        if (ev.key === "ArrowDown") { active = Math.min(active + 1, last); refresh(); return true; }
        if (ev.key === "ArrowUp") { active = Math.max(active - 1, 0); refresh(); return true; }
        if (ev.key === "Backspace") { chosen[active] = null; refresh(); return true; }
        return false;
      }
    };
  }

  function ratingPanel(panel, refresh) {
    var n = S.labels.length;
    var values = S.criteria.map(function () { return S.labels.map(function () { return null; }); });  // null: not moved
    var drawn = false;
    var shown = [];     // every slider, top to bottom: {ci, slot, out, input}
    var active = 0;     // the slider the keys move (as the desktop's highlighted one)
    function setValue(i, v) {
      var s = shown[i];
      s.input.value = String(Math.max(0, Math.min(100, v)));
      values[s.ci][s.slot] = Number(s.input.value);
      s.input.focus();
      refresh();
    }
    function draw() {
      // drawn once: sliders keep focus and position while the participant moves them
      if (drawn) {
        shown.forEach(function (s) { s.out.textContent = values[s.ci][s.slot] === null ? S.texts.unset : String(values[s.ci][s.slot]); });
        return;
      }
      drawn = true;
      S.criteria.forEach(function (c, ci) {
        var row = el("div", {"class": "criterion", "data-criterion": c.id});
        row.appendChild(el("h3", {text: c.label + ": " + c.question}));
        for (var slot = 0; slot < n; slot++) {
          var input = el("input", {type: "range", min: "0", max: "100", step: "1", value: "50",
            id: "rate-" + c.id + "-" + slot, "aria-label": S.labels[slot]});
          var out = el("output", {id: "value-" + c.id + "-" + slot, text: S.texts.unset});
          (function (input, ci, slot, at) {
            input.addEventListener("input", function () { values[ci][slot] = Number(input.value); refresh(); });
            input.addEventListener("focus", function () { active = at; });
          })(input, ci, slot, shown.length);
          shown.push({ci: ci, slot: slot, out: out, input: input});
          row.appendChild(el("div", {"class": "slider"}, el("strong", {text: S.labels[slot]}), input, out));
        }
        if (S.anchors.length) {
          var scale = el("div", {"class": "anchors"});
          S.anchors.forEach(function (a) { scale.appendChild(el("span", {text: a})); });
          row.appendChild(scale);
        }
        panel.appendChild(row);
      });
    }
    return {
      size: -1,   // no start hint: the sliders' keys are the browser's own (see instructions.how_rating)
      draw: draw,
      missing: function () {
        var out = [];
        S.criteria.forEach(function (c, ci) {
          values[ci].forEach(function (v, slot) { if (v === null) out.push(c.label + " " + S.labels[slot]); });
        });
        return out;
      },
      answer: function () {
        var ratings = {};
        S.criteria.forEach(function (c, ci) {
          ratings[c.id] = {};
          values[ci].forEach(function (v, slot) { if (v !== null) ratings[c.id][String(slot)] = v; });
        });
        return {ratings: ratings};
      },
      // the desktop's keys (instructions.how_rating): Up/Down choose a slider, the number keys jump to
      // S.points; Left/Right and Page Up/Down are the focused slider's own, else they move the chosen one
      key: function (ev) {
        if (ev.target && ev.target.type === "range") {
          for (var i = 0; i < shown.length; i++) if (shown[i].input === ev.target) active = i;
        }
        if (ev.key === "ArrowUp" || ev.key === "ArrowDown") {
          active = Math.max(0, Math.min(shown.length - 1, active + (ev.key === "ArrowDown" ? 1 : -1)));
          shown[active].input.focus();
          return true;
        }
        var k = Number(ev.key);
        if (k >= 1 && k <= S.points.length) { setValue(active, S.points[k - 1]); return true; }
        if (ev.target && ev.target.type === "range") return false;
        var step = {ArrowLeft: -1, ArrowRight: 1, PageDown: -10, PageUp: 10}[ev.key];
        if (!step) return false;
        var cur = values[shown[active].ci][shown[active].slot];
        setValue(active, cur === null ? 50 : cur + step);
        return true;
      }
    };
  }

  // ------------------------------------------------------------------ the questionnaire
  function questionnaire() {
    var b = shell(S.heading);
    b.appendChild(el("p", {text: S.intro}));
    var form = el("form", {id: "questionnaire"});
    S.items.forEach(function (q) {
      var f = el("fieldset", {"data-item": q.id}, el("legend", {text: q.text}));
      if (q.kind === "likert") {
        var scale = el("div", {"class": "likert"}, el("span", {"class": "anchor", text: q.anchors[0]}));
        for (var p = 1; p <= q.points; p++) {
          scale.appendChild(el("label", {}, el("input", {type: "radio", name: q.id, value: String(p), id: "q-" + q.id + "-" + p}),
            el("span", {text: String(p)})));
        }
        scale.appendChild(el("span", {"class": "anchor", text: q.anchors[1]}));
        f.appendChild(scale);
      } else if (q.kind === "choice") {
        if (q.hint) f.appendChild(el("p", {"class": "note", text: q.hint}));
        q.options.forEach(function (o, i) {
          f.appendChild(el("label", {"class": "option"}, el("input", {type: q.multiple ? "checkbox" : "radio", name: q.id,
            value: o, id: "q-" + q.id + "-" + (i + 1)}), el("span", {text: o})));
        });
      } else if (q.kind === "number") {
        f.appendChild(el("p", {"class": "note", text: q.hint}));
        f.appendChild(el("input", {type: "text", inputmode: q.integer ? "numeric" : "decimal", name: q.id, id: "q-" + q.id}));
      } else {
        f.appendChild(el("textarea", {name: q.id, id: "q-" + q.id, rows: "3", maxlength: "5000"}));
      }
      form.appendChild(f);
    });
    b.appendChild(form);
    function send() {
      var answers = {};
      S.items.forEach(function (q) {
        var inputs = form.querySelectorAll("[name='" + q.id + "']");
        if (q.kind === "likert" || (q.kind === "choice" && !q.multiple)) {
          inputs.forEach(function (i) { if (i.checked) answers[q.id] = q.kind === "likert" ? Number(i.value) : i.value; });
        } else if (q.kind === "choice") {
          var chosen = [];
          inputs.forEach(function (i) { if (i.checked) chosen.push(i.value); });
          if (chosen.length) answers[q.id] = chosen;
        } else {
          var v = inputs[0].value;
          if (v !== "" || q.kind === "text") answers[q.id] = v;
        }
      });
      post("questionnaire", {answers: answers});
    }
    form.addEventListener("submit", function (ev) { ev.preventDefault(); send(); });
    b.appendChild(button("submit", S.button, send));
  }

  function render() {
    switch (S.screen) {
      case "welcome": return welcome();
      case "back": return back();
      case "block": return block();
      case "instructions": return instructions();
      case "soundcheck": return soundcheck();
      case "trial": return trial();
      case "questionnaire": return questionnaire();
      case "done": return final();
      default: { var b = shell(S.heading); b.appendChild(paragraphs(S.text)); }
    }
  }
  render();
})();
