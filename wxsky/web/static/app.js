// wxsky instructor station (docs/web.md): one WebSocket at /ws. The daemon pushes `hello`,
// `view`, `reply` and `error` as JSON text frames and the picture as binary JPEG frames; the
// page sends {"id", "cmd", "params"} and shows each reply in #message.
'use strict';

(() => {
  // ------------------------------------------------------------------ units and formats
  const FT_PER_M = 3.280839895;
  const KT_PER_MPS = 1.943844492;
  const INHG_PER_HPA = 0.02952998751;
  const M_PER_SM = 1609.344;
  const WIDTH_MIN = 160, WIDTH_MAX = 1920;
  const BACKOFF_MIN_MS = 1000, BACKOFF_MAX_MS = 10000;

  const $ = (sel, root = document) => root.querySelector(sel);
  const $$ = (sel, root = document) => Array.from(root.querySelectorAll(sel));
  const isNum = (x) => typeof x === 'number' && Number.isFinite(x);

  const fmtInt = (x) => (isNum(x) ? String(Math.round(x)) : '–');
  const fmt1 = (x) => (isNum(x) ? x.toFixed(1) : '–');
  const ft = (m) => Math.round((m * FT_PER_M) / 10) * 10;
  const mFt = (m) => (isNum(m) ? `${Math.round(m)} m` : '–');
  const kt = (mps) => Math.round(mps * KT_PER_MPS);
  const dir3 = (d) => String(Math.round(((d % 360) + 360) % 360) || 360).padStart(3, '0');
  const pct = (x) => (isNum(x) ? `${Math.round(x * 100)} %` : '–');

  function oktaCode(n) {
    if (!isNum(n)) return '';
    if (n <= 0) return 'SKC';
    if (n <= 2) return 'FEW';
    if (n <= 4) return 'SCT';
    if (n <= 7) return 'BKN';
    return 'OVC';
  }

  function visSub(m) {
    if (!isNum(m)) return '';
    if (m >= 10000) return `${(m / 1000).toFixed(0)} km · ${(m / M_PER_SM).toFixed(m >= 16000 ? 0 : 1)} SM`;
    return `${(m / M_PER_SM).toFixed(m < 1600 ? 2 : 1)} SM`;
  }

  // "2026-06-21T13:00:09.861372Z" -> {date: "2026-06-21", time: "13:00:09", hm: "13:00"}
  function splitUtc(t) {
    const m = /^(\d{4}-\d{2}-\d{2})[T ](\d{2}):(\d{2})(?::(\d{2}))?/.exec(String(t || ''));
    if (!m) return null;
    return { date: m[1], time: `${m[2]}:${m[3]}:${m[4] || '00'}`, hm: `${m[2]}:${m[3]}` };
  }

  function longDate(d) {
    const dt = new Date(`${d}T00:00:00Z`);
    if (Number.isNaN(dt.getTime())) return d;
    return dt.toLocaleDateString('en-GB', {
      weekday: 'short', day: 'numeric', month: 'short', year: 'numeric', timeZone: 'UTC',
    });
  }

  // DOM: el('td', {class: 'x', title: 't'}, 'text', child, ...); text goes in as text.
  function el(tag, attrs = {}, ...children) {
    const node = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (v === undefined || v === null || v === false) continue;
      if (k === 'class') node.className = v;
      else if (k === 'dataset') Object.assign(node.dataset, v);
      else node.setAttribute(k, v === true ? '' : String(v));
    }
    for (const c of children.flat()) {
      if (c === null || c === undefined || c === false) continue;
      node.append(typeof c === 'object' ? c : document.createTextNode(String(c)));
    }
    return node;
  }
  // A value with its second unit under it, smaller.
  const val = (main, sub) => [el('span', { class: 'v' }, main), sub ? el('span', { class: 'sub' }, sub) : null];
  const setText = (node, text) => { if (node && node.textContent !== text) node.textContent = text; };

  // Re-render a container only when what it shows has changed (keeps tooltips and scroll).
  const shown = new Map();
  function renderIf(key, data, draw) {
    const sig = JSON.stringify(data);
    if (shown.get(key) === sig) return;
    shown.set(key, sig);
    draw();
  }

  // ------------------------------------------------------------------ state
  const state = {
    ws: null,
    backoff: BACKOFF_MIN_MS,
    everConnected: false,
    nextId: 1,
    pending: new Map(), // id -> {cmd, label, onOk, quiet}
    hello: null,
    view: null,
    prefilled: false,
    lastWidthSent: 0,
    frozen: false,
    picture: { busy: false, next: null, url: null, times: [] },
  };

  // ------------------------------------------------------------------ messages
  let messageTimer = 0;
  function showMessage(text, kind) {
    const box = $('#message');
    clearTimeout(messageTimer);
    box.textContent = text;
    box.classList.remove('ok', 'error', 'pending');
    if (kind) box.classList.add(kind);
    box.title = text ? `${text} (tap to dismiss)` : '';
    if (kind === 'ok') messageTimer = setTimeout(() => showMessage('', null), 6000);
  }

  // ------------------------------------------------------------------ the connection
  function wsUrl() {
    return (location.protocol === 'https:' ? 'wss' : 'ws') + '://' + location.host + '/ws';
  }

  function setConnection(up, retryMs) {
    const c = $('#connection');
    c.classList.toggle('ok', up);
    c.classList.toggle('down', !up);
    if (up) { c.textContent = 'connected'; c.title = wsUrl(); }
    else if (state.everConnected || retryMs !== undefined) {
      c.textContent = 'reconnecting…';
      c.title = retryMs ? `next try in ${Math.round(retryMs / 1000)} s` : '';
    } else c.textContent = 'connecting…';
    document.body.classList.toggle('offline', !up);
  }

  function connect() {
    let ws;
    try {
      ws = new WebSocket(wsUrl());
    } catch (e) {
      scheduleReconnect();
      return;
    }
    ws.binaryType = 'blob';
    state.ws = ws;
    ws.onopen = () => {
      state.backoff = BACKOFF_MIN_MS;
      state.everConnected = true;
      setConnection(true);
      state.lastWidthSent = 0;
      sendWidth();
    };
    ws.onmessage = (ev) => {
      if (typeof ev.data === 'string') onText(ev.data);
      else onPicture(ev.data);
    };
    ws.onclose = () => {
      if (state.ws !== ws) return;
      state.ws = null;
      for (const [, p] of state.pending) {
        if (!p.quiet) showMessage(`${p.label || p.cmd}: no answer, the connection closed`, 'error');
      }
      state.pending.clear();
      scheduleReconnect();
    };
    ws.onerror = () => { /* a close follows */ };
  }

  function scheduleReconnect() {
    const delay = state.backoff;
    state.backoff = Math.min(state.backoff * 2, BACKOFF_MAX_MS);
    setConnection(false, delay);
    setTimeout(connect, delay);
  }

  const encoder = new TextEncoder();
  // One command; `label` names it in #message, `onOk(result)` runs on an ok reply.
  function send(cmd, params, { label, okText, onOk, quiet } = {}) {
    const ws = state.ws;
    if (!ws || ws.readyState !== WebSocket.OPEN) {
      if (!quiet) showMessage(`${label || cmd}: not connected to the daemon`, 'error');
      return null;
    }
    const id = state.nextId++;
    const msg = { id, cmd };
    if (params !== undefined) msg.params = params;
    const text = JSON.stringify(msg);
    const limit = state.hello?.max_message_bytes;
    if (isNum(limit) && encoder.encode(text).length > limit) {
      showMessage(`${label || cmd}: the request is larger than the daemon takes (${limit} bytes)`, 'error');
      return null;
    }
    state.pending.set(id, { cmd, label, okText, onOk, quiet });
    ws.send(text);
    if (!quiet) showMessage(`${label || cmd}…`, 'pending');
    return id;
  }

  function onText(text) {
    let msg;
    try {
      msg = JSON.parse(text);
    } catch (e) {
      return;
    }
    if (!msg || typeof msg !== 'object') return;
    switch (msg.type) {
      case 'hello': onHello(msg); break;
      case 'view': onView(msg); break;
      case 'reply': onReply(msg); break;
      case 'error': showMessage(`daemon: ${msg.error ?? 'error'}`, 'error'); break;
      default: break; // unknown types are for newer pages
    }
  }

  function onReply(msg) {
    const p = state.pending.get(msg.id);
    if (!p) return;
    state.pending.delete(msg.id);
    if (msg.ok) {
      try {
        p.onOk?.(msg.result);
      } catch (e) {
        console.error(e);
      }
      if (!p.quiet) {
        const t = typeof p.okText === 'function' ? p.okText(msg.result) : p.okText;
        showMessage(`✓ ${t || `${p.label || p.cmd}: done`}`, 'ok');
      }
    } else {
      showMessage(String(msg.error || `${p.label || p.cmd}: refused`), 'error');
    }
  }

  // ------------------------------------------------------------------ the picture
  const picture = () => $('#picture');

  function onPicture(data) {
    const blob = data instanceof Blob && data.type === 'image/jpeg' ? data : new Blob([data], { type: 'image/jpeg' });
    const pic = state.picture;
    if (pic.busy) { pic.next = blob; return; } // a slow decoder shows the newest frame only
    showBlob(blob);
  }

  function showBlob(blob) {
    const pic = state.picture;
    const img = picture();
    const url = URL.createObjectURL(blob);
    pic.busy = true;
    const done = (ok) => {
      img.onload = img.onerror = null;
      if (ok) {
        if (pic.url) URL.revokeObjectURL(pic.url);
        pic.url = url;
        const now = performance.now();
        pic.times.push(now);
        while (pic.times.length && now - pic.times[0] > 5000) pic.times.shift();
        if (img.naturalWidth && img.naturalHeight) {
          const ratio = `${img.naturalWidth} / ${img.naturalHeight}`;
          const frame = $('#picture-frame');
          if (frame.style.aspectRatio !== ratio) frame.style.aspectRatio = ratio;
        }
        $('#picture-frame').classList.add('live');
      } else {
        URL.revokeObjectURL(url);
      }
      pic.busy = false;
      if (pic.next) {
        const next = pic.next;
        pic.next = null;
        showBlob(next);
      }
    };
    img.onload = () => done(true);
    img.onerror = () => done(false);
    img.src = url;
  }

  function pictureRate() {
    const t = state.picture.times;
    if (t.length < 2 || performance.now() - t[t.length - 1] > 3000) return 0;
    return (t.length - 1) / ((t[t.length - 1] - t[0]) / 1000);
  }

  // The picture's displayed width in device pixels, sent on connect and when it changes.
  let widthTimer = 0;
  function wantedWidth() {
    const css = picture().getBoundingClientRect().width || $('#picture-frame').clientWidth;
    const w = Math.round(css * (window.devicePixelRatio || 1));
    return Math.min(WIDTH_MAX, Math.max(WIDTH_MIN, w));
  }
  function sendWidth() {
    const w = wantedWidth();
    if (w === state.lastWidthSent) return;
    if (send('view', { width_px: w }, { quiet: true }) !== null) state.lastWidthSent = w;
  }
  function watchWidth() {
    const ro = new ResizeObserver(() => {
      clearTimeout(widthTimer);
      widthTimer = setTimeout(sendWidth, 200);
    });
    ro.observe(picture());
  }

  // ------------------------------------------------------------------ hello
  function onHello(h) {
    state.hello = h;
    fillPresets(h.presets || []);
    const types = Array.isArray(h.cloud_types) ? h.cloud_types : [];
    for (const sel of $$('.layer-type')) fillTypes(sel, types, sel.value);
    const kind = $('#precip-kind');
    const keep = kind.value;
    kind.replaceChildren(el('option', { value: '' }, 'none'),
      ...(h.precipitation || []).map((c) => el('option', { value: c }, c)));
    kind.value = keep;
    if (kind.value !== keep) kind.value = '';
    // Buttons for commands this daemon does not have stay disabled.
    const known = Array.isArray(h.commands) ? new Set(h.commands) : null;
    for (const b of $$('button[data-cmd]')) {
      b.disabled = !!known && !known.has(b.dataset.cmd);
      if (b.disabled) b.title = `this daemon has no ${b.dataset.cmd}`;
    }
  }

  function fillPresets(list) {
    const sel = $('#preset-select');
    const keep = sel.value;
    const opts = list.map((p) => {
      const o = el('option', { value: p.name },
        p.description ? `${p.name} — ${p.description}` : p.name);
      if (p.origin) o.title = p.origin;
      return o;
    });
    sel.replaceChildren(...opts);
    if (keep && list.some((p) => p.name === keep)) sel.value = keep;
  }

  function fillTypes(sel, types, current) {
    const list = [...types];
    if (current && !list.includes(current)) list.push(current);
    sel.replaceChildren(...list.map((t) => el('option', { value: t }, t)));
    if (current) sel.value = current;
  }

  // ------------------------------------------------------------------ view
  function onView(v) {
    state.view = v;
    const tasks = [renderPerf, renderWeather, renderWind, renderClock, renderInputs,
      renderStations, renderModel, renderDaemon, renderFreeze, showCurrentRvr];
    for (const t of tasks) {
      try {
        t(v);
      } catch (e) {
        console.error(e);
      }
    }
    // The forms are filled from the target once, on the first view, and again only when the
    // instructor asks (load current): never under the instructor's fingers.
    if (!state.prefilled && v.target) {
      state.prefilled = true;
      loadAll(v);
    }
  }

  function renderPerf(v) {
    const parts = [];
    parts.push(`fps ${fmt1(v.fps)}`);
    if (isNum(v.fps) && v.fps > 0) parts.push(`frame ${fmt1(1000 / v.fps)} ms`);
    if (isNum(v.frame_gap_ms)) parts.push(`largest gap ${Math.round(v.frame_gap_ms)} ms`);
    if (v.ring) {
      parts.push(`ring rebuilds ${v.ring.rebuilds ?? 0}${v.ring.busy ? ' (building)' : ''}`);
    }
    const r = pictureRate();
    const cap = state.hello?.picture_fps;
    parts.push(`picture ${r.toFixed(1)}/s${isNum(cap) ? ` of ${cap}` : ''}`);
    setText($('#perf'), parts.join('  ·  '));
  }

  // --- weather
  function layerText(l) {
    if (!l) return null;
    return {
      // A blend of stations or a transition gives fractions of an okta: shown as they are.
      main: `${oktaCode(l.cover_oktas)} ${Number.isInteger(l.cover_oktas) ? l.cover_oktas : (+l.cover_oktas).toFixed(1)}/8 ${l.type}`,
      sub: `${Math.round(l.base_m)}–${Math.round(l.top_m)} m · ${ft(l.base_m)}–${ft(l.top_m)} ft`,
    };
  }
  function windText(w) {
    if (!w) return { main: 'calm', sub: '' };
    const d = w.variable ? 'VRB' : `${dir3(w.dir_deg)}°`;
    const gust = w.gust_mps > 0 ? ` G${fmt1(w.gust_mps)}` : '';
    return {
      main: `${d} ${fmt1(w.speed_mps)}${gust} m/s`,
      sub: `${w.variable ? 'VRB' : dir3(w.dir_deg)}${String(kt(w.speed_mps)).padStart(2, '0')}${w.gust_mps > 0 ? 'G' + kt(w.gust_mps) : ''}KT`,
    };
  }
  function fogText(f) {
    if (!f || (!isNum(f.visibility_m) && !(f.rvr || []).length)) return { main: 'none', sub: '' };
    const bits = [];
    bits.push(isNum(f.visibility_m) ? `${Math.round(f.visibility_m)} m` : 'RVR fog');
    if (isNum(f.depth_m)) bits.push(`${Math.round(f.depth_m)} m deep`);
    if (f.patchy) bits.push('patchy');
    const rvr = (f.rvr || []).map((r) => `RVR ${r.runway} ${Math.round(r.rvr_m)} m (${ft(r.rvr_m)} ft)`);
    return { main: bits.join(', '), sub: rvr.join(' · ') };
  }
  function precipText(list) {
    if (!list || !list.length) return { main: 'none', sub: '' };
    return {
      main: list.map((p) => `${p.kind}${isNum(p.coverage_pct) ? ` ${Math.round(p.coverage_pct)} %` : ''}`).join(', '),
      sub: list.map((p) => (isNum(p.visibility_m) ? `vis ${Math.round(p.visibility_m)} m` : '')).filter(Boolean).join(' · '),
    };
  }
  const pwText = (pw) => ({ main: pw && pw.length ? pw.join(' ') : 'none', sub: '' });

  function weatherRows(a, t) {
    const src = t.sources || {};
    const rows = [];
    const add = (field, key, fa, ft_, sources) => rows.push({ field, key, a: fa, t: ft_, src: sources });
    add('Visibility', 'visibility',
      { main: mFt(a.visibility_m), sub: visSub(a.visibility_m) },
      { main: mFt(t.visibility_m), sub: visSub(t.visibility_m) }, [src.visibility_m]);
    const n = Math.max((a.layers || []).length, (t.layers || []).length);
    if (n === 0) add('Clouds', 'layers', { main: 'none', sub: '' }, { main: 'none', sub: '' }, [src.layers]);
    for (let i = 0; i < n; i++) {
      add(`Cloud layer ${i + 1}`, `layer${i}`,
        layerText(a.layers?.[i]) || { main: '—', sub: '' },
        layerText(t.layers?.[i]) || { main: '—', sub: '' }, [src.layers]);
    }
    add('Wind (surface)', 'wind', windText(a.wind?.[0]), windText(t.wind?.[0]), [src.wind]);
    add('Temperature / dewpoint', 'air',
      { main: `${fmt1(a.temperature_c)} / ${fmt1(a.dewpoint_c)} °C`, sub: spread(a) },
      { main: `${fmt1(t.temperature_c)} / ${fmt1(t.dewpoint_c)} °C`, sub: spread(t) },
      [src.temperature_c, src.dewpoint_c]);
    add('QNH', 'qnh',
      { main: `${fmtInt(a.qnh_hpa)} hPa`, sub: isNum(a.qnh_hpa) ? `${(a.qnh_hpa * INHG_PER_HPA).toFixed(2)} inHg` : '' },
      { main: `${fmtInt(t.qnh_hpa)} hPa`, sub: isNum(t.qnh_hpa) ? `${(t.qnh_hpa * INHG_PER_HPA).toFixed(2)} inHg` : '' },
      [src.qnh_hpa]);
    add('Present weather', 'pw', pwText(a.present_weather), pwText(t.present_weather), [src.present_weather]);
    if ((a.precipitation || []).length || (t.precipitation || []).length) {
      add('Precipitation', 'precip', precipText(a.precipitation), precipText(t.precipitation), [src.precipitation]);
    }
    add('Fog / RVR', 'fog', fogText(a.fog), fogText(t.fog), [src.fog]);
    return rows;
  }
  function spread(w) {
    if (!isNum(w.temperature_c) || !isNum(w.dewpoint_c)) return '';
    return `spread ${(w.temperature_c - w.dewpoint_c).toFixed(1)} °C`;
  }

  function sourceTag(names) {
    const list = [...new Set(names.filter(Boolean))];
    if (!list.length) return el('span', { class: 'src' }, '–');
    return list.map((n) => el('span', { class: `src src-${String(n).replace(/[^a-z0-9-]/gi, '')}` }, n));
  }

  function renderWeather(v) {
    const a = v.weather, t = v.target;
    if (!a || !t) return;
    const rows = weatherRows(a, t);
    const moving = rows.filter((r) => r.a.main !== r.t.main || r.a.sub !== r.t.sub).length;
    renderIf('weather', rows, () => {
      const body = $('#weather-table tbody');
      body.replaceChildren(...rows.map((r) => {
        const mv = r.a.main !== r.t.main || r.a.sub !== r.t.sub;
        return el('tr', { class: mv ? 'moving' : null, dataset: { field: r.key } },
          el('th', { scope: 'row' }, r.field, mv ? el('span', { class: 'moving-mark', title: 'moving toward the target' }, ' ▸') : null),
          el('td', {}, val(r.a.main, r.a.sub)),
          el('td', {}, val(r.t.main, r.t.sub)),
          el('td', {}, sourceTag(r.src)));
      }));
    });
    // The target alone, for a glance (and for tests).
    setText($('#target-visibility'), isNum(t.visibility_m) ? `${Math.round(t.visibility_m)} m` : '–');
    const layers = t.layers || [];
    renderIf('target-layers', layers, () => {
      $('#target-layers').replaceChildren(...layers.map((l) => el('li', {
        dataset: { baseM: String(l.base_m) }, class: 'chip',
        title: `${l.type}, ${l.cover_oktas}/8, ${Math.round(l.base_m)}–${Math.round(l.top_m)} m MSL`,
      }, `${oktaCode(l.cover_oktas)} ${l.type} ${Math.round(l.base_m)} m / ${ft(l.base_m)} ft`)));
    });
    // Settled, and the overrides held.
    const ws = $('#weather-state');
    const settled = !!v.settled;
    setText(ws, settled ? 'settled' : (moving ? `moving · ${moving} field${moving > 1 ? 's' : ''}` : 'moving'));
    ws.classList.toggle('settled', settled);
    ws.classList.toggle('moving', !settled);
    const ov = v.overrides || {};
    const names = Object.keys(ov).sort();
    renderIf('overrides', names.map((n) => [n, ov[n]?.source, Math.round(ov[n]?.expires_in_s ?? -1)]), () => {
      const p = $('#overrides');
      if (!names.length) { p.replaceChildren('no overrides held: the weather follows its feeds'); return; }
      p.replaceChildren('overrides held: ', ...names.map((n) => {
        const o = ov[n] || {};
        const exp = isNum(o.expires_in_s) ? `, ${Math.max(0, Math.round(o.expires_in_s))} s left` : '';
        return el('span', { class: `ov src-${o.source || ''}`, title: isNum(o.age_s) ? `set ${Math.round(o.age_s)} s ago${exp}` : '' },
          `${n} (${o.source || '?'}${exp})`);
      }));
    });
  }

  // --- wind
  function renderWind(v) {
    const a = v.weather?.wind || [];
    const t = v.target?.wind || [];
    const rows = a.map((w, i) => {
      const tw = t[i];
      const mv = !tw || Math.round(tw.alt_m) !== Math.round(w.alt_m) || Math.round(tw.dir_deg) !== Math.round(w.dir_deg)
        || fmt1(tw.speed_mps) !== fmt1(w.speed_mps) || fmt1(tw.gust_mps) !== fmt1(w.gust_mps);
      return [Math.round(w.alt_m), Math.round(w.dir_deg), fmt1(w.speed_mps), fmt1(w.gust_mps), !!w.variable, mv];
    });
    renderIf('wind', rows, () => {
      $('#wind-table tbody').replaceChildren(...a.map((w, i) => el('tr', { class: rows[i][5] ? 'moving' : null },
        el('td', {}, val(`${Math.round(w.alt_m)} m`, `${ft(w.alt_m)} ft`)),
        el('td', {}, w.variable ? val('VRB', `${dir3(w.dir_deg)}°`) : val(`${dir3(w.dir_deg)}°`, '')),
        el('td', {}, val(`${fmt1(w.speed_mps)} m/s`, `${kt(w.speed_mps)} kt`)),
        el('td', {}, w.gust_mps > 0 ? val(`${fmt1(w.gust_mps)} m/s`, `${kt(w.gust_mps)} kt`) : val('—', '')))));
      if (!a.length) $('#wind-table tbody').replaceChildren(el('tr', {}, el('td', { colspan: 4, class: 'muted' }, 'no wind levels')));
      $('#wind-profile').replaceChildren(window.WxskyDraw.windProfile(a, v.weather?.observer?.alt_m));
    });
  }

  // --- clock, sun and moon
  function renderClock(v) {
    const c = v.clock || {};
    const sp = splitUtc(c.time_utc);
    setText($('#topclock'), sp ? `${sp.time} UTC${c.frozen ? ' · frozen' : ''}` : '--:--:-- UTC');
    $('#topclock').classList.toggle('frozen', !!c.frozen);
    const sun = v.sun || {}, moon = v.moon || {};
    const data = [sp, c.rate, c.frozen, c.at_end, fmt1(sun.elevation_deg), fmt1(sun.azimuth_deg),
      fmt1(moon.elevation_deg), fmt1(moon.azimuth_deg), pct(moon.illuminated)];
    renderIf('clock', data, () => {
      const body = el('div', { class: 'clock-body' },
        el('div', { class: 'clock-main' },
          el('div', { class: 'clock-time' }, sp ? sp.time : '--:--:--', el('span', { class: 'clock-z' }, ' UTC')),
          el('div', { class: 'clock-date' }, sp ? longDate(sp.date) : ''),
          el('div', { class: 'badges' },
            el('span', { class: 'badge' }, `rate ×${isNum(c.rate) ? +c.rate.toFixed(3) : '?'}`),
            c.frozen ? el('span', { class: 'badge warn' }, 'frozen') : el('span', { class: 'badge ok' }, 'running'),
            c.at_end ? el('span', { class: 'badge warn', title: 'the clock reached the end of its range' }, 'at end') : null)),
        el('dl', { class: 'kv bodies' },
          el('dt', {}, el('span', { class: 'dot sun' }), 'Sun'),
          el('dd', {}, `el ${fmt1(sun.elevation_deg)}°  az ${fmtInt(sun.azimuth_deg)}°`,
            isNum(sun.elevation_deg) && sun.elevation_deg < 0 ? el('span', { class: 'muted' }, ' (below horizon)') : null),
          el('dt', {}, el('span', { class: 'dot moon' }), 'Moon'),
          el('dd', {}, `el ${fmt1(moon.elevation_deg)}°  az ${fmtInt(moon.azimuth_deg)}°`,
            el('span', { class: 'muted' }, `  ${pct(moon.illuminated)} lit`))),
        window.WxskyDraw.skyDome(sun, moon));
      $('#clock').replaceChildren(body);
    });
  }

  // --- inputs: rows updated in place, keyed by name (tooltips survive the updates)
  function shortName(name) {
    const colon = name.indexOf(':');
    const slash = name.lastIndexOf('/');
    if (colon < 0 || slash < colon) return name;
    return `${name.slice(0, colon)}:…/${name.slice(slash + 1)}`;
  }
  function clipText(text, n) {
    return text.length > n ? `${text.slice(0, n - 1)}…` : text;
  }

  function renderInputs(v) {
    const body = $('#inputs-table tbody');
    const list = Array.isArray(v.inputs) ? v.inputs : [];
    const seen = new Set();
    list.forEach((inp, i) => {
      const name = String(inp.name);
      seen.add(name);
      let tr = $$('tr', body).find((r) => r.dataset.name === name);
      if (!tr) {
        tr = el('tr', { dataset: { name } },
          el('td', { class: 'in-name' }), el('td', { class: 'in-kind' }), el('td', { class: 'in-state' }),
          el('td', { class: 'num in-msgs' }), el('td', { class: 'num in-errs' }), el('td', { class: 'in-last' }));
      }
      if (body.children[i] !== tr) body.insertBefore(tr, body.children[i] || null);
      const down = !inp.ok;
      tr.classList.toggle('down', down);
      const [cName, cKind, cState, cMsgs, cErrs, cLast] = tr.children;
      // A feed or a link is named by its path or URL: its last part says which one, the
      // whole is in the tooltip.
      setText(cName, shortName(name));
      if (cName.title !== name) cName.title = name;
      setText(cKind, String(inp.kind ?? ''));
      setText(cState, down ? 'DOWN' : 'OK');
      cState.className = `in-state ${down ? 'state-down' : 'state-ok'}`;
      setText(cMsgs, isNum(inp.messages) ? String(inp.messages) : '–');
      setText(cErrs, isNum(inp.errors) ? String(inp.errors) : '–');
      const last = String(inp.last_error || (down && inp.reason) || '');
      setText(cLast, last ? clipText(last, 90) : '—');
      const tip = [inp.last_error, inp.reason && inp.reason !== inp.last_error ? `(${inp.reason})` : '']
        .filter(Boolean).join(' ');
      if (cLast.title !== tip) cLast.title = tip;
      cErrs.classList.toggle('has-errors', (inp.errors || 0) > 0);
    });
    for (const tr of $$('tr', body)) if (!seen.has(tr.dataset.name)) tr.remove();
    const downs = list.filter((i) => !i.ok).length;
    setText($('#inputs-panel h2'), downs ? `Inputs · ${downs} down` : 'Inputs');
    $('#inputs-panel').classList.toggle('alert', downs > 0);
  }

  // --- stations
  function renderStations(v) {
    const st = Array.isArray(v.stations) ? v.stations : [];
    const obs = v.target?.observer || v.weather?.observer;
    renderIf('stations', [st, obs], () => {
      const box = $('#stations-map');
      const table = $('#stations-table');
      if (!st.length) {
        box.replaceChildren(el('p', { class: 'empty' }, 'no METAR stations in use'));
        table.hidden = true;
        return;
      }
      box.replaceChildren(window.WxskyDraw.stationsMap(obs, st));
      table.hidden = false;
      const sorted = [...st].sort((x, y) => (y.weight || 0) - (x.weight || 0));
      $('tbody', table).replaceChildren(...sorted.map((s) => el('tr', {},
        el('td', {}, String(s.station)),
        el('td', { class: 'num' }, isNum(s.distance_km) ? `${fmt1(s.distance_km)} km` : '–',
          el('span', { class: 'sub' }, isNum(s.distance_km) ? ` ${Math.round(s.distance_km / 1.852)} NM` : '')),
        el('td', { class: 'num' }, isNum(s.weight) ? `${(s.weight * 100).toFixed(0)} %` : '–'),
        el('td', {}, obsTime(s.observed_utc)))));
    });
  }
  function obsTime(t) {
    const sp = splitUtc(t);
    return sp ? `${sp.date.slice(8)}/${sp.hm}Z` : String(t ?? '–');
  }

  // --- model data
  function renderModel(v) {
    const panel = $('#model-panel');
    const m = v.model;
    panel.hidden = !m;
    if (!m) return;
    renderIf('model', m, () => {
      const steps = Array.isArray(m.steps_utc) ? m.steps_utc.map(obsTime).join(', ') : '–';
      const rows = [
        ['Steps', steps || '–'],
        ['METAR weight', isNum(m.metar_weight) ? m.metar_weight.toFixed(2) : '–'],
      ];
      if (m.profile) {
        const p = m.profile;
        if ('freezing_level_m' in p) rows.push(['Freezing level', isNum(p.freezing_level_m) ? `${Math.round(p.freezing_level_m)} m · ${ft(p.freezing_level_m)} ft` : '–']);
        if ('tropopause_m' in p) rows.push(['Tropopause', isNum(p.tropopause_m) ? `${Math.round(p.tropopause_m)} m · ${ft(p.tropopause_m)} ft` : '–']);
      }
      if (m.reason) rows.push(['Reason', String(m.reason)]);
      $('#model').replaceChildren(...rows.flatMap(([k, x]) => [el('dt', {}, k), el('dd', {}, x)]));
    });
  }

  // --- daemon
  function renderDaemon(v) {
    const ch = v.channel || {};
    let role = ch.role || '–';
    const bits = [];
    if (ch.name) bits.push(`"${ch.name}"`);
    if (ch.site) bits.push(`site ${ch.site}`);
    if (ch.role === 'channel') bits.push(ch.master_alive ? 'master alive' : 'master GONE');
    if (isNum(ch.lag_ms)) bits.push(`lag ${Math.round(ch.lag_ms)} ms`);
    const peers = ch.peers && typeof ch.peers === 'object' ? Object.keys(ch.peers).length : 0;
    if (peers) bits.push(`${peers} peer${peers > 1 ? 's' : ''}`);
    if (bits.length) role += ` · ${bits.join(', ')}`;
    const rows = [
      ['Pages connected', isNum(v.clients) ? String(v.clients) : '–'],
      ['Frame rate', `${fmt1(v.fps)} fps`],
      ['Frames published', isNum(v.frames_published) ? v.frames_published.toLocaleString('en-US') : '–'],
      ['Channel role', role],
    ];
    if (state.hello) {
      rows.push(['Version', `${state.hello.version ?? '?'} · this page is client ${state.hello.client_id ?? '?'}`]);
    }
    renderIf('daemon', rows, () => {
      $('#daemon').replaceChildren(...rows.flatMap(([k, x]) => [el('dt', {}, k), el('dd', {}, x)]));
    });
  }

  function renderFreeze(v) {
    const frozen = !!v.clock?.frozen;
    state.frozen = frozen;
    const b = $('#freeze');
    setText(b, frozen ? 'Unfreeze' : 'Freeze');
    b.setAttribute('aria-pressed', String(frozen));
    b.classList.toggle('active', frozen);
  }

  // ------------------------------------------------------------------ forms: prefill
  function loadAll(v) {
    loadLayers(v);
    loadVisibility(v);
    loadWindForm(v);
    loadAir(v);
    loadTime(v);
    loadPrecip(v);
  }

  const num = (input) => {
    const s = String(input.value).trim();
    if (s === '') return null;
    const x = Number(s);
    return Number.isFinite(x) ? x : NaN;
  };
  const setVal = (input, x, digits = 0) => {
    input.value = isNum(x) ? (digits ? String(+x.toFixed(digits)) : String(Math.round(x))) : '';
    input.dispatchEvent(new Event('input', { bubbles: true }));
  };

  // --- cloud layers
  function addLayerRow(l) {
    const row = $('#layer-row-template').content.firstElementChild.cloneNode(true);
    fillTypes($('.layer-type', row), state.hello?.cloud_types || ['cumulus'], l?.type || 'cumulus');
    $('#layers-editor').append(row);
    setVal($('.layer-cover', row), l?.cover_oktas ?? 3);
    setVal($('.layer-base', row), l?.base_m);
    setVal($('.layer-top', row), l?.top_m);
    layersChanged();
    return row;
  }
  function loadLayers(v) {
    $('#layers-editor').replaceChildren();
    for (const l of v.target?.layers || []) addLayerRow(l);
    layersChanged();
  }
  function layersChanged() {
    $('#layers-empty').hidden = $$('.layer-row').length > 0;
  }
  function layersFromForm() {
    const out = [];
    for (const [i, row] of $$('#layers-editor .layer-row').entries()) {
      const layer = {
        type: $('.layer-type', row).value,
        cover_oktas: num($('.layer-cover', row)),
        base_m: num($('.layer-base', row)),
        top_m: num($('.layer-top', row)),
      };
      for (const k of ['cover_oktas', 'base_m', 'top_m']) {
        if (!isNum(layer[k])) throw new Error(`layer ${i + 1}: ${k.replace('_', ' ')} needs a number`);
      }
      out.push(layer);
    }
    return out;
  }

  // --- visibility and fog
  function loadVisibility(v) {
    const t = v.target || {};
    setVal($('#vis-input'), t.visibility_m);
    const f = t.fog;
    setVal($('#fog-vis-input'), f?.visibility_m);
    setVal($('#fog-depth-input'), f?.depth_m ?? 100);
    const r = f?.rvr?.[0];
    $('#rvr-runway').value = r?.runway ?? '';
    setVal($('#rvr-input'), r?.rvr_m);
    showCurrentRvr();
  }
  function showCurrentRvr() {
    const f = state.view?.target?.fog;
    const list = f?.rvr || [];
    setText($('#rvr-current'), fogText(f).main !== 'none'
      ? `now: ${fogText(f).main}${list.length ? '; ' + list.map((r) => `RVR ${r.runway} ${Math.round(r.rvr_m)} m`).join(', ') : ''}`
      : 'now: no fog');
  }

  // --- wind
  function addWindRow(w) {
    const row = $('#wind-row-template').content.firstElementChild.cloneNode(true);
    $('#wind-editor').append(row);
    setVal($('.wind-alt', row), w?.alt_m);
    setVal($('.wind-dir', row), w?.dir_deg);
    setVal($('.wind-speed', row), w?.speed_mps, 1);
    setVal($('.wind-gust', row), w?.gust_mps ?? 0, 1);
    $('.wind-var', row).checked = !!w?.variable;
    return row;
  }
  function loadWindForm(v) {
    $('#wind-editor').replaceChildren();
    for (const w of v.target?.wind || []) addWindRow(w);
  }
  function windFromForm() {
    return $$('#wind-editor .wind-row').map((row, i) => {
      const w = {
        alt_m: num($('.wind-alt', row)),
        dir_deg: num($('.wind-dir', row)),
        speed_mps: num($('.wind-speed', row)),
        gust_mps: num($('.wind-gust', row)) ?? 0,
        variable: $('.wind-var', row).checked,
      };
      for (const k of ['alt_m', 'dir_deg', 'speed_mps', 'gust_mps']) {
        if (!isNum(w[k])) throw new Error(`wind level ${i + 1}: ${k.replace(/_/g, ' ')} needs a number`);
      }
      return w;
    });
  }

  // --- air
  function loadAir(v) {
    const t = v.target || {};
    setVal($('#temp-input'), t.temperature_c, 1);
    setVal($('#dew-input'), t.dewpoint_c, 1);
    setVal($('#qnh-input'), t.qnh_hpa, 1);
  }

  // --- time
  function loadTime(v) {
    const sp = splitUtc(v.clock?.time_utc || v.target?.time_utc);
    if (sp) {
      $('#date-input').value = sp.date;
      $('#time-input').value = sp.hm;
    }
    if (isNum(v.clock?.rate)) $('#rate-input').value = String(v.clock.rate);
  }

  // --- precipitation
  function loadPrecip(v) {
    const pw = v.target?.present_weather || [];
    const kinds = state.hello?.precipitation || [];
    for (const g of pw) {
      const m = /^([+-]?)(.*)$/.exec(g);
      if (m && kinds.includes(m[2])) {
        $('#precip-kind').value = m[2];
        $('#precip-intensity').value = m[1];
        return;
      }
    }
    $('#precip-kind').value = '';
  }

  // ------------------------------------------------------------------ forms: live hints
  function hintFor(input) {
    const x = num(input);
    const row = input.closest('.layer-row, .wind-row, label');
    if (input.matches('.layer-base, .layer-top')) {
      setText(input.closest('label').querySelector('.ft'), isNum(x) ? `${ft(x)} ft` : '');
    } else if (input.matches('.layer-cover')) {
      setText($('.okta-code', row), isNum(x) ? oktaCode(x) : '');
    } else if (input.matches('.wind-alt')) {
      setText(input.parentElement.querySelector('.ft'), isNum(x) ? `${ft(x)} ft` : '');
    } else if (input.matches('.wind-speed, .wind-gust')) {
      setText(input.parentElement.querySelector('.kt'), isNum(x) ? `${kt(x)} kt` : '');
    } else if (input.id === 'vis-input') {
      setText($('#vis-hint'), visSub(x));
    } else if (input.id === 'rvr-input') {
      setText($('#rvr-hint'), isNum(x) ? `${ft(x)} ft` : '');
    } else if (input.id === 'qnh-input') {
      setText($('#qnh-hint'), isNum(x) ? `${(x * INHG_PER_HPA).toFixed(2)} inHg` : '');
    }
  }

  // ------------------------------------------------------------------ controls
  const now = () => $('#apply-now').checked;
  const withNow = (params) => (now() ? { ...params, now: true } : params);
  const fail = (text) => showMessage(text, 'error');

  function setWeather(params, label, okText) {
    send('set_weather', withNow(params), {
      label,
      okText: `${okText}${now() ? ', at once' : ''}`,
    });
  }

  function wireControls() {
    $('#message').addEventListener('click', () => showMessage('', null));

    // presets
    $('#preset-apply').addEventListener('click', () => {
      const name = $('#preset-select').value;
      if (!name) return fail('apply preset: choose a preset first');
      send('apply_preset', { name, now: now() }, {
        label: `apply preset ${name}`, okText: `preset ${name} applied${now() ? ' at once' : ''}`,
      });
    });
    $('#release').addEventListener('click', () => {
      send('release', { now: now() }, { label: 'release', okText: 'released: the feeds set the weather again' });
    });
    $('#preset-save').addEventListener('click', () => {
      const name = $('#save-name').value.trim();
      const description = $('#save-description').value.trim();
      if (!name) return fail('save preset: give it a name');
      const params = { name, description };
      if ($('#save-force').checked) params.force = true;
      send('save_preset', params, {
        label: `save preset ${name}`, okText: `saved the target weather as preset ${name}`,
        onOk: () => {
          send('presets', undefined, {
            quiet: true,
            onOk: (result) => {
              const list = Array.isArray(result) ? result : result?.presets;
              if (Array.isArray(list)) {
                fillPresets(list);
                if (list.some((p) => p.name === name)) $('#preset-select').value = name;
              }
            },
          });
        },
      });
    });

    // clouds
    $('#layer-add').addEventListener('click', () => {
      const rows = $$('#layers-editor .layer-row');
      const last = rows.length ? num($('.layer-top', rows[rows.length - 1])) : null;
      const obs = state.view?.target?.observer?.alt_m ?? 0;
      const base = isNum(last) ? Math.round((last + 300) / 10) * 10 : Math.round((obs + 1000) / 10) * 10;
      const row = addLayerRow({ type: 'cumulus', cover_oktas: 3, base_m: base, top_m: base + 600 });
      $('.layer-type', row).focus();
    });
    $('#layers-editor').addEventListener('click', (ev) => {
      const b = ev.target.closest('.layer-remove');
      if (!b) return;
      b.closest('.layer-row').remove();
      layersChanged();
    });
    $('#layers-load').addEventListener('click', () => {
      if (!state.view) return fail('no weather from the daemon yet');
      loadLayers(state.view);
    });
    $('#layers-apply').addEventListener('click', () => {
      let layers;
      try {
        layers = layersFromForm();
      } catch (e) {
        return fail(`set clouds: ${e.message}`);
      }
      setWeather({ layers }, 'set clouds', layers.length ? `clouds set: ${layers.length} layer${layers.length > 1 ? 's' : ''}` : 'clouds cleared');
    });

    // visibility, fog, RVR
    $('#vis-load').addEventListener('click', () => state.view && loadVisibility(state.view));
    $('#vis-apply').addEventListener('click', () => {
      const x = num($('#vis-input'));
      if (!isNum(x)) return fail('set visibility: give the visibility in metres');
      setWeather({ visibility_m: x }, 'set visibility', `visibility set to ${Math.round(x)} m`);
    });
    $('#rvr-apply').addEventListener('click', () => {
      const runway = $('#rvr-runway').value.trim().toUpperCase();
      const rvr = num($('#rvr-input'));
      const fogVis = num($('#fog-vis-input'));
      const depth = num($('#fog-depth-input'));
      if (Number.isNaN(fogVis) || Number.isNaN(depth)) return fail('set fog: the fog visibility and depth are numbers (m)');
      if (runway && !isNum(rvr)) return fail(`set RVR: give runway ${runway}'s RVR in metres`);
      if (!runway && isNum(rvr)) return fail('set RVR: give the runway, e.g. 14 or 32L');
      // Keep the other runways' RVRs; this runway's is replaced.
      const current = state.view?.target?.fog?.rvr || [];
      const list = current.filter((r) => r.runway !== runway).map((r) => ({ runway: r.runway, rvr_m: r.rvr_m }));
      if (runway) list.push({ runway, rvr_m: rvr });
      if (!list.length && !isNum(fogVis)) return fail('set fog: give a fog visibility, or a runway and its RVR');
      const fog = { depth_m: isNum(depth) ? depth : 100, rvr: list };
      if (isNum(fogVis)) fog.visibility_m = fogVis;
      setWeather({ fog }, 'set fog', runway ? `RVR ${runway} set to ${Math.round(rvr)} m` : 'fog set');
    });
    $('#rvr-clear').addEventListener('click', () => {
      // docs/fog.md: `fog = {}` clears the fog and its RVRs.
      setWeather({ fog: {} }, 'clear fog', 'fog and RVR cleared');
    });

    // wind
    $('#wind-add').addEventListener('click', () => {
      const rows = $$('#wind-editor .wind-row');
      const last = rows.length ? num($('.wind-alt', rows[rows.length - 1])) : null;
      const row = addWindRow({
        alt_m: isNum(last) ? last + 1000 : (state.view?.target?.observer?.alt_m ?? 0) + 10,
        dir_deg: 270, speed_mps: 5, gust_mps: 0,
      });
      $('.wind-alt', row).focus();
    });
    $('#wind-editor').addEventListener('click', (ev) => {
      const b = ev.target.closest('.wind-remove');
      if (b) b.closest('.wind-row').remove();
    });
    $('#wind-load').addEventListener('click', () => state.view && loadWindForm(state.view));
    $('#wind-apply').addEventListener('click', () => {
      let wind;
      try {
        wind = windFromForm();
      } catch (e) {
        return fail(`set wind: ${e.message}`);
      }
      if (!wind.length) return fail('set wind: give at least one level');
      setWeather({ wind }, 'set wind', `wind set: ${wind.length} level${wind.length > 1 ? 's' : ''}`);
    });

    // precipitation
    $('#precip-apply').addEventListener('click', () => {
      const kind = $('#precip-kind').value;
      const pw = kind ? [$('#precip-intensity').value + kind] : [];
      setWeather({ present_weather: pw }, 'set precipitation', pw.length ? `present weather ${pw[0]}` : 'precipitation cleared');
    });

    // temperature, dewpoint, QNH
    $('#air-load').addEventListener('click', () => state.view && loadAir(state.view));
    $('#air-apply').addEventListener('click', () => {
      const p = {};
      const tc = num($('#temp-input')), dc = num($('#dew-input')), q = num($('#qnh-input'));
      if ([tc, dc, q].some(Number.isNaN)) return fail('set air: temperature, dewpoint and QNH are numbers');
      if (isNum(tc)) p.temperature_c = tc;
      if (isNum(dc)) p.dewpoint_c = dc;
      if (isNum(q)) p.qnh_hpa = q;
      if (!Object.keys(p).length) return fail('set air: give a temperature, dewpoint or QNH');
      setWeather(p, 'set temperature and QNH', 'temperature and QNH set');
    });

    // time
    $('#time-load').addEventListener('click', () => state.view && loadTime(state.view));
    $('#time-apply').addEventListener('click', () => {
      const d = $('#date-input').value, t = $('#time-input').value;
      if (!/^\d{4}-\d{2}-\d{2}$/.test(d) || !/^\d{2}:\d{2}/.test(t)) return fail('set time: give the date and the time (UTC)');
      const time_utc = `${d}T${t.slice(0, 5)}:00Z`;
      send('set_time', { time_utc }, { label: 'set time', okText: `clock set to ${time_utc}` });
    });
    $('#rate-apply').addEventListener('click', () => {
      const rate = num($('#rate-input'));
      if (!isNum(rate)) return fail('set rate: give the clock rate (1 = real time)');
      send('set_time', { rate }, { label: 'set clock rate', okText: `clock rate ×${rate}` });
    });
    $('#freeze').addEventListener('click', () => {
      const frozen = !state.frozen;
      send('freeze', { frozen }, {
        label: frozen ? 'freeze' : 'unfreeze',
        okText: frozen ? 'weather frozen' : 'weather running again',
      });
    });

    // live unit hints beside the inputs
    document.addEventListener('input', (ev) => {
      if (ev.target instanceof HTMLInputElement) hintFor(ev.target);
    });
    // Enter in a field presses its section's main button.
    $('#controls').addEventListener('keydown', (ev) => {
      if (ev.key !== 'Enter' || !(ev.target instanceof HTMLInputElement) || ev.target.type === 'checkbox') return;
      const sec = ev.target.closest('.row')?.querySelector('button.primary') || ev.target.closest('section')?.querySelector('button.primary');
      if (sec && !sec.disabled) { ev.preventDefault(); sec.click(); }
    });
  }

  // ------------------------------------------------------------------ start
  function start() {
    wireControls();
    watchWidth();
    setConnection(false);
    connect();
    // The picture rate decays on the perf line even when no view comes.
    setInterval(() => { if (state.view) renderPerf(state.view); }, 1000);
  }

  if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', start);
  else start();
})();
