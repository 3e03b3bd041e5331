// wxsky instructor station: the inline SVG drawings (no library, no tiles): the METAR
// stations around the observer, the wind barbs by height and the sun and moon on the sky dome.
// Everything here builds SVG elements from numbers; text goes in as textContent only.
'use strict';

(() => {
  const NS = 'http://www.w3.org/2000/svg';
  const KT_PER_MPS = 1.943844492;
  const FT_PER_M = 3.280839895;
  const KM_PER_DEG_LAT = 110.574;
  const KM_PER_DEG_LON = 111.320; // at the equator; times cos(latitude)

  function s(tag, attrs = {}, ...children) {
    const node = document.createElementNS(NS, tag);
    for (const [k, v] of Object.entries(attrs)) {
      if (v !== undefined && v !== null) node.setAttribute(k, String(v));
    }
    for (const c of children) {
      if (c === null || c === undefined || c === false) continue;
      node.append(typeof c === 'string' ? document.createTextNode(c) : c);
    }
    return node;
  }

  const r1 = (x) => Math.round(x * 10) / 10;

  // A round number at least x: 1, 1.5, 2, 2.5, 3, 4, 5, 6 or 8 times a power of ten.
  function niceCeil(x) {
    if (!(x > 0)) return 1;
    const p = Math.pow(10, Math.floor(Math.log10(x)));
    for (const m of [1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10]) if (m * p >= x - 1e-9) return m * p;
    return 10 * p;
  }

  // Where a label goes: beside its dot, on the first side where it overlaps no label placed
  // so far and no other dot (else the side that overlaps least). Text width is estimated.
  function placeLabels(items, W, H) {
    const boxes = [];
    const overlap = (a, b) => Math.max(0, Math.min(a.x2, b.x2) - Math.max(a.x1, b.x1))
      * Math.max(0, Math.min(a.y2, b.y2) - Math.max(a.y1, b.y1));
    for (const it of items) {
      const w = it.text.length * 7.2, h = 14, g = it.r + 4;
      const cands = [
        { x: it.x + g, y: it.y + 4, anchor: 'start', box: { x1: it.x + g, x2: it.x + g + w, y1: it.y - 8, y2: it.y + 6 } },
        { x: it.x - g, y: it.y + 4, anchor: 'end', box: { x1: it.x - g - w, x2: it.x - g, y1: it.y - 8, y2: it.y + 6 } },
        { x: it.x, y: it.y - g - 3, anchor: 'middle', box: { x1: it.x - w / 2, x2: it.x + w / 2, y1: it.y - g - h, y2: it.y - g } },
        { x: it.x, y: it.y + g + 11, anchor: 'middle', box: { x1: it.x - w / 2, x2: it.x + w / 2, y1: it.y + g, y2: it.y + g + h } },
        { x: it.x + g * 0.7, y: it.y - g * 0.7 - 2, anchor: 'start', box: { x1: it.x + g * 0.7, x2: it.x + g * 0.7 + w, y1: it.y - g * 0.7 - 13, y2: it.y - g * 0.7 + 1 } },
        { x: it.x + g * 0.7, y: it.y + g * 0.7 + 10, anchor: 'start', box: { x1: it.x + g * 0.7, x2: it.x + g * 0.7 + w, y1: it.y + g * 0.7 - 1, y2: it.y + g * 0.7 + 13 } },
      ];
      let best = null, bestCost = Infinity;
      for (const c of cands) {
        let cost = 0;
        for (const b of boxes) cost += overlap(c.box, b);
        for (const o of items) {
          if (o === it) continue;
          cost += overlap(c.box, { x1: o.x - o.r, x2: o.x + o.r, y1: o.y - o.r, y2: o.y + o.r }) * 0.5;
        }
        if (c.box.x1 < 0 || c.box.x2 > W || c.box.y1 < 0 || c.box.y2 > H) cost += 5000;
        if (cost < bestCost - 1e-6) { best = c; bestCost = cost; }
        if (cost === 0) break;
      }
      it.label = best;
      boxes.push(best.box);
    }
  }

  // ---------------------------------------------------------------- the stations map
  // Equirectangular around the observer: east and north in km, scaled so the farthest
  // station sits inside a round-numbered distance ring.
  function stationsMap(observer, stations) {
    const W = 420, H = 320, cx = W / 2, cy = H / 2 + 4, R = Math.min(W, H) / 2 - 34;
    const lat0 = observer?.lat_deg ?? 0, lon0 = observer?.lon_deg ?? 0;
    const cosLat = Math.cos((lat0 * Math.PI) / 180);
    const pts = stations.map((st) => {
      let dlon = st.lon_deg - lon0;
      if (dlon > 180) dlon -= 360;
      if (dlon < -180) dlon += 360;
      const east = dlon * KM_PER_DEG_LON * cosLat;
      const north = (st.lat_deg - lat0) * KM_PER_DEG_LAT;
      return { st, east, north, d: Math.hypot(east, north) };
    });
    const far = Math.max(1, ...pts.map((p) => p.d), ...stations.map((st) => st.distance_km || 0));
    const ring = niceCeil(far);
    const k = R / ring;

    const svg = s('svg', {
      viewBox: `0 0 ${W} ${H}`, class: 'map-svg', role: 'img',
      'aria-label': `METAR stations within ${ring} km of the observer`,
    });
    // Rings: the round distance and its half, with the km (and NM) label.
    svg.append(
      s('circle', { cx, cy, r: R, class: 'map-ring' }),
      s('circle', { cx, cy, r: R / 2, class: 'map-ring minor' }),
      s('line', { x1: cx - R - 8, y1: cy, x2: cx + R + 8, y2: cy, class: 'map-axis' }),
      s('line', { x1: cx, y1: cy - R - 8, x2: cx, y2: cy + R + 8, class: 'map-axis' }),
      s('text', { x: cx + R * 0.7071 + 4, y: cy - R * 0.7071 - 4, class: 'map-ring-label' },
        `${ring} km`),
      s('text', { x: cx + R * 0.7071 + 4, y: cy - R * 0.7071 + 10, class: 'map-ring-sub' },
        `${Math.round(ring / 1.852)} NM`),
      s('text', { x: cx + (R / 2) * 0.7071 + 3, y: cy - (R / 2) * 0.7071 - 3, class: 'map-ring-sub' },
        `${ring / 2}`),
      s('text', { x: cx, y: cy - R - 12, class: 'map-north' }, 'N'),
    );
    // Labels placed heaviest first (they get the best spots); dots drawn heaviest last, on top.
    const items = pts.map((p) => {
      const w = Math.max(0, Math.min(1, Number(p.st.weight) || 0));
      return { p, w, x: cx + p.east * k, y: cy - p.north * k, r: 3.5 + 13 * Math.sqrt(w),
        text: `${p.st.station} ${Math.round(w * 100)}%` };
    });
    placeLabels([...items].sort((a, b) => b.w - a.w), W, H);
    const dots = s('g', { class: 'map-stations' });
    const labels = s('g', { class: 'map-labels' });
    for (const it of [...items].sort((a, b) => a.w - b.w)) {
      dots.append(
        s('g', { class: 'map-station' },
          s('title', {}, `${it.p.st.station}: weight ${(it.w * 100).toFixed(1)} %, `
            + `${r1(it.p.st.distance_km ?? it.p.d)} km, observed ${it.p.st.observed_utc ?? '?'}`),
          s('circle', { cx: it.x, cy: it.y, r: it.r, class: 'map-dot' }),
          s('circle', { cx: it.x, cy: it.y, r: 1.8, class: 'map-dot-core' }),
        ),
      );
      labels.append(s('text', {
        x: it.label.x, y: it.label.y, class: 'map-label', 'text-anchor': it.label.anchor,
      }, it.text));
    }
    svg.append(dots);
    // The observer: a cross-hair at the centre.
    svg.append(
      s('g', { class: 'map-observer' },
        s('title', {}, `observer ${lat0.toFixed(4)}°, ${lon0.toFixed(4)}°`),
        s('circle', { cx, cy, r: 6 }),
        s('line', { x1: cx - 11, y1: cy, x2: cx + 11, y2: cy }),
        s('line', { x1: cx, y1: cy - 11, x2: cx, y2: cy + 11 }),
      ),
      labels,
    );
    return svg;
  }

  // ---------------------------------------------------------------- wind barbs
  // A barb in knots (pennant 50, feather 10, half feather 5), its staff pointing where the
  // wind comes from, feathers on the clockwise side; a circle under 3 kt (calm).
  function barb(x, y, dirDeg, speedMps, variable) {
    const kt = Math.max(0, speedMps * KT_PER_MPS);
    const g = s('g', { class: 'barb', transform: `translate(${x} ${y})` });
    if (kt < 2.5) {
      g.append(s('circle', { r: 5, class: 'barb-calm' }), s('circle', { r: 1.5, class: 'barb-dot' }));
      return g;
    }
    const L = 34, step = 5.5, fl = 13;
    const rot = s('g', { transform: `rotate(${dirDeg})` });
    rot.append(s('line', { x1: 0, y1: 0, x2: 0, y2: -L, class: 'barb-staff' }));
    let rest = Math.round(kt / 5) * 5;
    let pos = -L;
    const pennants = Math.floor(rest / 50); rest -= pennants * 50;
    const full = Math.floor(rest / 10); rest -= full * 10;
    const half = rest >= 5;
    for (let i = 0; i < pennants; i++) {
      rot.append(s('polygon', {
        points: `0,${pos} ${fl},${pos - 3} 0,${pos + step * 1.2}`, class: 'barb-pennant',
      }));
      pos += step * 1.4;
    }
    for (let i = 0; i < full; i++) {
      rot.append(s('line', { x1: 0, y1: pos, x2: fl, y2: pos - 5, class: 'barb-feather' }));
      pos += step;
    }
    if (half) {
      if (pennants === 0 && full === 0) pos += step; // a lone half feather sits off the end
      rot.append(s('line', { x1: 0, y1: pos, x2: fl / 2, y2: pos - 2.5, class: 'barb-feather' }));
    }
    g.append(rot, s('circle', { r: 2, class: 'barb-dot' }));
    if (variable) g.append(s('text', { x: 0, y: 16, class: 'barb-vrb' }, 'VRB'));
    return g;
  }

  // The levels on a height axis (MSL), a barb at each, the speed in knots beside it.
  function windProfile(levels, observerAltM) {
    const W = 190, H = 256, top = 26, bottom = H - 36, xb = 104;
    const svg = s('svg', { viewBox: `0 0 ${W} ${H}`, class: 'wind-svg', role: 'img',
      'aria-label': 'wind barbs by height' });
    if (!levels.length) {
      svg.append(s('text', { x: W / 2, y: H / 2, class: 'svg-empty' }, 'no wind levels'));
      return svg;
    }
    const sorted = [...levels].sort((a, b) => a.alt_m - b.alt_m);
    const ground = Math.min(observerAltM ?? sorted[0].alt_m, sorted[0].alt_m);
    const hiM = Math.max(...sorted.map((l) => l.alt_m));
    const span = Math.max(500, hiM - ground);
    const y = (alt) => bottom - ((alt - ground) / span) * (bottom - top);
    svg.append(
      s('line', { x1: 44, y1: top - 12, x2: 44, y2: bottom + 18, class: 'wp-axis' }),
      s('line', { x1: 38, y1: bottom + 18, x2: W - 6, y2: bottom + 18, class: 'wp-ground' }),
      s('text', { x: W - 4, y: bottom + 29, class: 'wp-axis-label', 'text-anchor': 'end' },
        `ground ${Math.round((ground * FT_PER_M) / 10) * 10} ft`),
    );
    // Keep labels apart when two levels are close.
    let lastY = Infinity;
    for (const l of sorted) {
      let yy = y(l.alt_m);
      if (lastY - yy < 26) yy = lastY - 26;
      lastY = yy;
      const ft = Math.round((l.alt_m * FT_PER_M) / 100) * 100;
      svg.append(
        s('line', { x1: 40, y1: y(l.alt_m), x2: 48, y2: y(l.alt_m), class: 'wp-tick' }),
        s('text', { x: 36, y: yy + 4, class: 'wp-alt' }, `${ft}`),
        barb(xb, yy, l.dir_deg, l.speed_mps, l.variable),
        s('text', { x: W - 4, y: yy + 4, class: 'wp-kt' },
          `${Math.round(l.speed_mps * KT_PER_MPS)}${l.gust_mps > 0 ? 'G' + Math.round(l.gust_mps * KT_PER_MPS) : ''} kt`),
      );
    }
    svg.append(s('text', { x: 4, y: 12, class: 'wp-axis-label' }, 'ft MSL'));
    return svg;
  }

  // ---------------------------------------------------------------- the sky dome
  // Zenith at the centre, the horizon at the rim, north up; a body below the horizon
  // sits dimmed on the rim at its azimuth.
  function skyDome(sun, moon) {
    const W = 132, c = W / 2, R = 54;
    const svg = s('svg', { viewBox: `0 0 ${W} ${W}`, class: 'dome-svg', role: 'img',
      'aria-label': 'sun and moon on the sky' });
    svg.append(
      s('circle', { cx: c, cy: c, r: R, class: 'dome-rim' }),
      s('circle', { cx: c, cy: c, r: (R * 2) / 3, class: 'dome-ring' }),
      s('circle', { cx: c, cy: c, r: R / 3, class: 'dome-ring' }),
      s('text', { x: c, y: c - R - 3, class: 'dome-n' }, 'N'),
      s('text', { x: c + R + 3, y: c + 3, class: 'dome-n', 'text-anchor': 'start' }, 'E'),
      s('text', { x: c, y: c + R + 11, class: 'dome-n' }, 'S'),
      s('text', { x: c - R - 3, y: c + 3, class: 'dome-n', 'text-anchor': 'end' }, 'W'),
    );
    const place = (body, cls, rad) => {
      if (!body || typeof body.elevation_deg !== 'number') return;
      const el = body.elevation_deg, az = (body.azimuth_deg * Math.PI) / 180;
      const rr = el >= 0 ? (R * (90 - el)) / 90 : R;
      svg.append(s('circle', {
        cx: c + rr * Math.sin(az), cy: c - rr * Math.cos(az), r: rad,
        class: `${cls}${el < 0 ? ' below' : ''}`,
      }));
    };
    place(moon, 'dome-moon', 5);
    place(sun, 'dome-sun', 6.5);
    return svg;
  }

  window.WxskyDraw = { stationsMap, windProfile, skyDome, niceCeil };
})();
