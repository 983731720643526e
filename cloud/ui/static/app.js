// The live page: fetches with the key in the X-API-Key header, swaps server-rendered fragments,
// follows one session (page image, text read so far, ask, speak). No framework, no build step.
"use strict";

const KEY_SLOT = "darkread.key";
const POLL_MS = 1000;        // session state while watching (not rate-limited)
const LIST_POLL_MS = 2000;   // the session list
// page.png and ask share a per-key budget (DARKREAD_ASK_RATE_PER_MIN, 30 by default): polling
// spends at most 15 + 7.5 a minute, leaving the rest for the Ask and Speak buttons.
const MIN_IMAGE_GAP_MS = 4000;
const MIN_READ_GAP_MS = 8000;
const PAUSE_S = 3;           // no new frames for this long: the wearer stopped reading (the last line is spoken)

// -- the key -------------------------------------------------------------------------------------

// "#key=..." in the address: keep it for this tab and take it out of the address bar and history.
function takeKeyFromFragment() {
  const fragment = new URLSearchParams(location.hash.slice(1));
  const key = fragment.get("key");
  if (key !== null) {
    sessionStorage.setItem(KEY_SLOT, key);
    fragment.delete("key");
    const rest = fragment.toString();
    history.replaceState(null, "", location.pathname + location.search + (rest ? "#" + rest : ""));
  }
}

function storedKey() {
  return sessionStorage.getItem(KEY_SLOT) || "";
}

class Unauthorized extends Error {}

let slowUntil = 0;  // after a 429: no polling of limited routes before this time

function slowedDown() {
  return Date.now() < slowUntil;
}

async function api(path, options = {}) {
  const headers = new Headers(options.headers || {});
  const key = storedKey();
  if (key) headers.set("X-API-Key", key);
  const response = await fetch(path, { ...options, headers, cache: "no-store", credentials: "omit" });
  if (response.status === 401) throw new Unauthorized("the service did not accept the key");
  if (response.status === 429) {
    const wait = Number(response.headers.get("Retry-After")) || 5;
    slowUntil = Date.now() + wait * 1000;
  }
  return response;
}

async function failure(response) {
  try {
    const body = await response.json();
    if (typeof body.detail === "string") return body.detail;
  } catch (_) { /* not JSON */ }
  return `HTTP ${response.status}`;
}

// -- the login form ------------------------------------------------------------------------------

function showLogin(message) {
  const form = document.getElementById("login");
  document.getElementById("view").hidden = true;
  form.hidden = false;
  document.getElementById("login-error").textContent = message || "";
  document.getElementById("key").focus();
}

function whenLoggedIn(start) {
  const form = document.getElementById("login");
  form.addEventListener("submit", async (event) => {
    event.preventDefault();  // never submitted: the key must not end up in a URL
    sessionStorage.setItem(KEY_SLOT, document.getElementById("key").value);
    await open(start);
  });
  open(start);
}

async function open(start) {
  try {
    const probe = await api("/v1/sessions");
    if (probe.status === 403) {  // a key for streaming only, say
      showLogin(`That key may not read sessions: ${await failure(probe)}.`);
      return;
    }
    if (!probe.ok) throw new Error(await failure(probe));
  } catch (error) {
    if (error instanceof Unauthorized) {
      showLogin(storedKey() ? "That key was not accepted. Try again." : "");
      return;
    }
    showLogin(`The service cannot be reached: ${error.message}`);
    return;
  }
  document.getElementById("login").hidden = true;
  document.getElementById("key").value = "";
  document.getElementById("view").hidden = false;
  start();
}

// -- the session list ----------------------------------------------------------------------------

function watchSessionList() {
  const holder = document.getElementById("sessions");
  let shown = null;
  const refresh = async () => {
    try {
      const response = await api("/ui/sessions");
      if (!response.ok) throw new Error(await failure(response));
      const html = await response.text();
      if (html !== shown) {
        // Keep keyboard focus on the same session across the swap.
        const focused = document.activeElement && document.activeElement.dataset
          ? document.activeElement.dataset.session : undefined;
        holder.innerHTML = html;  // server-rendered and escaped
        shown = html;
        if (focused !== undefined) {
          const again = holder.querySelector(`[data-session="${CSS.escape(focused)}"]`);
          if (again) again.focus();
        }
      }
      holder.setAttribute("aria-busy", "false");
    } catch (error) {
      if (error instanceof Unauthorized) return showLogin("The key is no longer accepted.");
      holder.setAttribute("aria-busy", "false");
    }
    setTimeout(refresh, LIST_POLL_MS);
  };
  refresh();
}

// -- one session ---------------------------------------------------------------------------------

function watchSession(sessionId) {
  const base = `/v1/sessions/${encodeURIComponent(sessionId)}`;
  const status = document.getElementById("status");
  const image = document.getElementById("page-image");
  const caption = document.getElementById("page-caption");
  const text = document.getElementById("text");
  const askButton = document.getElementById("ask");
  const speakButton = document.getElementById("speak");
  const answer = document.getElementById("answer");
  const answerText = document.getElementById("answer-text");
  const answerMeta = document.getElementById("answer-meta");
  const voice = document.getElementById("voice");

  let imageOf = null;        // the session state the page image shows
  let textOf = null;         // the session state the text was read from
  let lastReadAt = 0;
  let reading = false;       // a read is in flight (it runs beside the image refreshes)
  let pageUrl = null;
  let voiceUrl = null;
  let pausedNow = false;     // no new frames for PAUSE_S

  const say = (message) => { status.textContent = message; };

  let lastImageAt = 0;
  async function refreshImage(info) {
    if (slowedDown() || Date.now() - lastImageAt < MIN_IMAGE_GAP_MS) return false;
    lastImageAt = Date.now();
    const response = await api(`${base}/page.png`);
    if (response.status === 409) {
      caption.textContent = "Waiting for the first frames.";
      return false;
    }
    if (!response.ok) throw new Error(await failure(response));
    const url = URL.createObjectURL(await response.blob());
    await new Promise((resolve) => { image.onload = resolve; image.onerror = resolve; image.src = url; });
    if (pageUrl) URL.revokeObjectURL(pageUrl);
    pageUrl = url;
    image.hidden = false;
    const count = info.mode === "pages" ? `${info.pages} pages` : `${info.frames} frames`;
    image.alt = `The page stitched so far from ${count}; its text is read out beside it.`;
    caption.textContent = `${count}, ${image.naturalWidth} × ${image.naturalHeight} pixels`;
    return true;
  }

  // New lines are appended (the live region announces only them); a changed reading replaces all.
  // Each line: { text, unclear } (an unclear line is shown as such, never its guess).
  function showText(lines) {
    const current = Array.from(text.children, (p) => p.textContent);
    const extends_ = current.length <= lines.length && current.every((line, i) => line === lines[i].text);
    if (!extends_) text.replaceChildren();
    for (const line of lines.slice(extends_ ? current.length : 0)) {
      const p = document.createElement("p");
      p.textContent = line.text;
      if (line.unclear) p.className = "unclear";
      text.append(p);
    }
  }

  const REASON_WORDS = { glasses_busy: "glasses busy", too_dark: "too dark", too_much_motion: "hold still", too_small: "too small", look_again: "look again" };
  const shownLine = (line) => (line.status === "unclear"
    ? { text: `Unclear line (${(line.reasons || []).map((r) => REASON_WORDS[r] || r).join(", ") || "look again"})`, unclear: true }
    : { text: line.text, unclear: false });

  async function ask() {
    const response = await api(`${base}/ask`, {
      method: "POST",
      headers: { "Content-Type": "application/json", Accept: "application/json" },
      body: JSON.stringify({ question: "what does this say" }),
    });
    if (!response.ok) throw new Error(await failure(response));
    return response.json();
  }

  const linesOf = (result) => (result.lines.length ? result.lines : result.text.split("\n").map((t) => ({ text: t })))
    .filter((line) => line.text.trim() || line.status === "unclear").map(shownLine);

  // Reads the page again when it changed, at most every MIN_READ_GAP_MS (OCR is the costly part).
  async function readAlong(state) {
    if (reading || state === textOf || slowedDown() || Date.now() - lastReadAt < MIN_READ_GAP_MS) return;
    reading = true;
    try {
      showText(linesOf(await ask()));
      textOf = state;
    } catch (error) {
      if (error instanceof Unauthorized) showLogin("The key is no longer accepted.");
    } finally {
      reading = false;
      lastReadAt = Date.now();
    }
  }

  // The live push (GET .../events, Server-Sent Events, where the service has it): each `page`
  // event carries the lines read so far, so the text follows without asking (the image is polled).
  // Read with fetch (EventSource cannot send the key header); on any failure, back to polling.
  let pushed = null;         // null: not tried yet, true: events arrive, false: polling
  async function listen() {
    pushed = false;
    let response;
    try {
      response = await api(`${base}/events`, { headers: { Accept: "text/event-stream" } });
    } catch (_) { return; }
    const type = response.headers.get("Content-Type") || "";
    if (!response.ok || !type.startsWith("text/event-stream") || !response.body) return;
    pushed = true;
    const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
    let buffer = "";
    try {
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += value.replace(/\r\n?/g, "\n");
        let end;
        while ((end = buffer.indexOf("\n\n")) >= 0) {
          const block = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          const fields = { event: "message", data: [] };
          for (const line of block.split("\n")) {
            if (line.startsWith(":")) continue;  // keep-alive comment
            const colon = line.indexOf(":");
            const name = colon < 0 ? line : line.slice(0, colon);
            const value_ = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
            if (name === "data") fields.data.push(value_);
            else if (name === "event") fields.event = value_;
          }
          if (fields.event === "page" && fields.data.length) await onPage(JSON.parse(fields.data.join("\n")));
        }
      }
    } catch (_) { /* the stream broke: polling takes over */ }
    pushed = null;  // try again on a later poll
  }

  async function onPage(event) {
    const lines = (event.lines || []).filter((line) => line.text.trim() || line.status === "unclear").map(shownLine);
    if (lines.length) showText(lines);
    latest = { page: event.page, count: (event.lines || []).length };
    queueReadyLines(false);
  }

  // Line by line (the "speak each line" switch): a line is ready once a later one is on the page
  // (the wearer moved on), the last one when the glasses pause. Each is spoken once, in order.
  const speakLines = document.getElementById("speak-lines");
  const lineVoice = document.getElementById("line-voice");
  let latest = null;         // the newest pushed page: { page, count } (count: its lines so far)
  const spokenUpTo = new Map();  // page -> lines already queued
  const lineQueue = [];
  let speakingLines = false;

  function queueReadyLines(paused) {
    if (!speakLines.checked || latest === null) return;
    const done = spokenUpTo.get(latest.page) || 0;
    const ready = paused ? latest.count : latest.count - 1;
    for (let line = done; line < ready; line++) lineQueue.push({ page: latest.page, line });
    spokenUpTo.set(latest.page, Math.max(done, ready));
    speakQueuedLines();
  }

  function playLine(url) {
    return new Promise((resolve) => {
      lineVoice.onended = resolve;
      lineVoice.onerror = resolve;
      lineVoice.src = url;
      lineVoice.play().catch(() => { say("Speaking is blocked by the browser: press Speak instead."); resolve(); });
    });
  }

  async function speakQueuedLines() {
    if (speakingLines) return;
    speakingLines = true;
    try {
      while (lineQueue.length && speakLines.checked) {
        const { page, line } = lineQueue.shift();
        const response = await api(`${base}/lines/${line}/speech?page=${page}`, { headers: { Accept: "audio/wav" } });
        if (!response.ok) {
          say(`Line ${line + 1} could not be spoken: ${await failure(response)}`);
          continue;
        }
        const url = URL.createObjectURL(await response.blob());
        await playLine(url);
        URL.revokeObjectURL(url);
        lineVoice.dataset.spoken = String(Number(lineVoice.dataset.spoken) + 1);
      }
    } catch (error) {
      if (error instanceof Unauthorized) showLogin("The key is no longer accepted.");
      else say(`Speaking lines stopped: ${error.message}`);
    } finally {
      speakingLines = false;
    }
  }

  speakLines.addEventListener("change", () => {
    if (!speakLines.checked) {
      lineQueue.length = 0;
      lineVoice.pause();
      return;
    }
    if (latest !== null) spokenUpTo.set(latest.page, 0);  // from the top of the page being read
    say("Each line will be spoken as it is read.");
    queueReadyLines(pausedNow);
  });

  async function follow() {
    try {
      const response = await api(base);
      if (response.status === 404) {
        say("No such session (yet): waiting for the glasses to connect.");
      } else if (!response.ok) {
        say(`The service answered: ${await failure(response)}`);
      } else {
        const info = await response.json();
        const state = `${info.last_seq}/${info.frames}/${info.pages}`;
        const age = Math.max(0, Date.now() / 1000 - info.updated_s);
        if (!speakingLines) {
          say(slowedDown() ? `${info.frames} frames; the service asked to slow down, updating again shortly.`
            : age < 5 ? `Live: ${info.frames} frames received.` : `${info.frames} frames; nothing new for ${Math.round(age)} s.`);
        }
        pausedNow = age >= PAUSE_S;
        if (pausedNow) queueReadyLines(true);  // the glasses paused: the last line is ready too
        if (pushed === null && info.mode === "frames" && info.frames > 0) listen();
        if (state !== imageOf && (await refreshImage(info))) imageOf = state;
        // Without the live push, read beside the image (not awaited: the image keeps growing meanwhile).
        if (!pushed && imageOf !== null) readAlong(state);
      }
    } catch (error) {
      if (error instanceof Unauthorized) return showLogin("The key is no longer accepted.");
      say(`Connection trouble: ${error.message}. Retrying.`);
    }
    setTimeout(follow, POLL_MS);
  }

  function busy(button, work) {
    return async () => {
      if (button.getAttribute("aria-disabled") === "true") return;
      button.setAttribute("aria-disabled", "true");
      try {
        await work();
      } catch (error) {
        if (error instanceof Unauthorized) showLogin("The key is no longer accepted.");
        else say(error.message);
      } finally {
        button.setAttribute("aria-disabled", "false");
      }
    };
  }

  askButton.addEventListener("click", busy(askButton, async () => {
    say("Reading the page…");
    answer.dataset.state = "reading";
    const result = await ask();
    answer.hidden = false;
    answerText.textContent = result.text.split("\n").join(" ") || "No text on the page yet.";
    answerMeta.textContent = `Read by ${result.backend} in ${Math.round(result.latency_ms)} ms.`;
    answer.dataset.state = "done";
    showText(linesOf(result));
    say("Answer ready.");
  }));

  speakButton.addEventListener("click", busy(speakButton, async () => {
    say("Preparing the spoken answer…");
    const response = await api(`${base}/ask`, { method: "POST", headers: { Accept: "audio/wav" } });
    if (!response.ok) throw new Error(await failure(response));
    const url = URL.createObjectURL(await response.blob());
    if (voiceUrl) URL.revokeObjectURL(voiceUrl);
    voiceUrl = url;
    voice.src = url;
    voice.hidden = false;
    voice.dataset.seconds = response.headers.get("X-Speech-Seconds") || "";
    say(`Speaking (${Number(voice.dataset.seconds).toFixed(1)} s).`);
    try {
      await voice.play();
    } catch (_) {
      say("The answer is ready: press play on the audio player.");
    }
  }));

  follow();
}

// -- start -----------------------------------------------------------------------------------------

document.addEventListener("DOMContentLoaded", () => {
  takeKeyFromFragment();
  const view = document.body.dataset.view;
  if (view === "index") whenLoggedIn(watchSessionList);
  else if (view === "session") whenLoggedIn(() => watchSession(document.body.dataset.session));
});
