// SPDX-License-Identifier: MIT
// The map, on Leaflet with its metre-based CRS (L.CRS.Simple: one unit is one metre, x east,
// y north): pan, zoom and pinch, a scale bar, one wall layer per floor and overlay layers for
// trails, ellipses, crumbs, landmarks and the base. The view changes only when the user moves it
// or presses "fit all" / "follow"; never on a data update. Trails are appended to as rows
// arrive, so an update costs the same after four hours as after a minute; a whole trail is
// rebuilt only when the timeline is dragged or a history fetch fills a gap.
import L from 'leaflet';
import 'leaflet/dist/leaflet.css';
import type { LevelWalls, NodeState, TrailRow, Wall } from './api';
import { ellipse95 } from './geometry';

/** A trail point is drawn when at least this far from the last one drawn (m). */
const TRAIL_STEP_M = 0.25;
/** Points per polyline piece of a trail: Leaflet re-projects a whole polyline when a point is
 *  added, so a trail is a chain of pieces and an append costs at most one piece's points. A
 *  full piece moves to a canvas of its own that live updates never redraw: a frame costs the
 *  growing pieces, the ellipses and the markers, not the incident's history. */
const CHUNK_POINTS = 128;
/** A time gap in a drawn trail longer than this (s) is filled when a history fetch covers it. */
const GAP_S = 2;

const COLOURS = {
  wall: '#8a93a0',
  trail: '#6b7480',
  selected: '#ffe066',
  ellipse: '#ff9a3c',
  agent: '#ff6a3c',
  alerted: '#ff3b3b',
  base: '#4aa8ff',
  landmark: '#c8a2ff',
  crumb: '#7fd17f',
};

const ll = (x: number, y: number): L.LatLng => L.latLng(y, x);

interface AgentDrawing {
  /** The trail's pieces, oldest first; the last one grows. */
  pieces: L.Polyline[];
  style: L.PolylineOptions;
  /** Time of the last trail row considered, and the position last drawn. */
  until: number;
  lastX: number;
  lastY: number;
  /** Times of the rows drawn, to find gaps a history fetch fills. */
  times: number[];
  ellipse: L.Polygon;
  marker: L.CircleMarker;
}

/** Counters for the tests and the soak test: appends stay cheap, rebuilds stay rare. */
export interface MapStats {
  appends: number;
  rebuilds: number;
  /** Of the rebuilds, those that filled a gap with fetched history (the live stream lagged). */
  gapFills: number;
  planLevel: number | null;
  planSegments: number;
  zoom: number;
  /** Pixels per metre. */
  scale: number;
  /** The view's centre (m). */
  center: [number, number];
  /** Pinch zoom on touch screens. */
  touchZoom: boolean;
}

export class IncidentMap {
  readonly map: L.Map;
  private readonly plan = L.layerGroup();
  /** The finished trail pieces' canvas (below the live one). */
  private readonly historyRenderer: L.Canvas;
  private readonly trails = L.layerGroup();
  private readonly ellipses = L.layerGroup();
  private readonly crumbs = L.layerGroup();
  private readonly landmarks = L.layerGroup();
  private readonly bases = L.layerGroup();
  private readonly agentsLayer = L.layerGroup();
  private readonly levelLayers = new Map<number, L.Polyline>();
  private singlePlan: L.Polyline | null = null;
  private readonly agents = new Map<string, AgentDrawing>();
  private readonly statics = new Map<string, L.CircleMarker>();
  private shownLevel: number | null = null;
  private planSegments = 0;
  private appends = 0;
  private rebuilds = 0;
  private gapFills = 0;
  private fitted = false;
  follow = false;

  constructor(element: HTMLElement, private readonly onPick: (id: string) => void) {
    this.map = L.map(element, {
      crs: L.CRS.Simple,
      minZoom: -6,
      maxZoom: 7,
      zoomSnap: 0.25,
      zoomDelta: 0.5,
      wheelPxPerZoomLevel: 120,
      attributionControl: false,
      preferCanvas: true, // one canvas for every vector: thousands of trail points stay fast
    });
    this.map.setView([0, 0], 2);
    this.map.createPane('trailHistory').style.zIndex = '390';
    this.historyRenderer = L.canvas({ pane: 'trailHistory' });
    L.control.scale({ imperial: false, maxWidth: 160, position: 'bottomleft' }).addTo(this.map);
    for (const layer of [this.plan, this.trails, this.ellipses, this.crumbs, this.landmarks, this.bases, this.agentsLayer]) {
      layer.addTo(this.map);
    }
    L.control
      .layers(undefined, {
        'Floor plan': this.plan,
        Trails: this.trails,
        'Ellipses (95 %)': this.ellipses,
        'Crumbs and beacons': this.crumbs,
        Landmarks: this.landmarks,
        Base: this.bases,
      }, { collapsed: true, position: 'topright' })
      .addTo(this.map);
  }

  /** The plan: one layer per level of a multi-level plan (only the shown level drawn). */
  setPlan(walls: Wall[], levels: LevelWalls[], shownLevel: number | null): void {
    const segments = (ws: Wall[]) => ws.map((w) => [ll(w[0], w[1]), ll(w[2], w[3])]);
    const style = { color: COLOURS.wall, weight: 2, opacity: 1, interactive: false };
    this.levelLayers.clear();
    for (const l of levels) this.levelLayers.set(l.level, L.polyline(segments(l.walls), style));
    this.singlePlan = levels.length ? null : L.polyline(segments(walls), style);
    this.showLevel(shownLevel);
  }

  showLevel(level: number | null): void {
    this.shownLevel = level;
    this.plan.clearLayers();
    const layer = level === null ? this.singlePlan : this.levelLayers.get(level) ?? this.singlePlan;
    if (layer) {
      this.plan.addLayer(layer);
      this.planSegments = (layer.getLatLngs() as L.LatLng[][]).length;
    } else {
      this.planSegments = 0;
    }
  }

  private agent(id: string): AgentDrawing {
    let a = this.agents.get(id);
    if (!a) {
      const style: L.PolylineOptions = { color: COLOURS.trail, weight: 1.5, opacity: 0.9, interactive: false };
      const ellipse = L.polygon([], { color: COLOURS.ellipse, weight: 1.5, fill: false, interactive: false });
      const marker = L.circleMarker([0, 0], { radius: 6, color: '#ffffff', weight: 1.5, fillColor: COLOURS.agent, fillOpacity: 1 });
      marker.bindTooltip(id, { permanent: true, direction: 'right', offset: [8, -8], className: 'agent-label' });
      marker.on('click', () => this.onPick(id));
      this.ellipses.addLayer(ellipse);
      this.agentsLayer.addLayer(marker);
      a = { pieces: [], style, until: -Infinity, lastX: NaN, lastY: NaN, times: [], ellipse, marker };
      this.agents.set(id, a);
    }
    return a;
  }

  /** Rows after what the trail already holds (live rows, or the tail of a history fetch). */
  appendTrail(id: string, rows: TrailRow[]): void {
    const a = this.agent(id);
    for (const r of rows) {
      if (!(r[0] > a.until)) continue;
      if (!this.accept(a, r)) continue;
      this.addPoint(a, ll(r[1], r[2]));
      this.appends++;
    }
  }

  /** A row considered for the trail: drawn (true) when at least TRAIL_STEP_M from the last
   *  point drawn; its time is the trail's end either way. */
  private accept(a: AgentDrawing, r: TrailRow): boolean {
    a.until = r[0];
    if (Number.isFinite(a.lastX) && Math.hypot(r[1] - a.lastX, r[2] - a.lastY) < TRAIL_STEP_M) return false;
    a.times.push(r[0]);
    a.lastX = r[1];
    a.lastY = r[2];
    return true;
  }

  /** A trail piece: on the history canvas when finished, else on the live one. */
  private piece(a: AgentDrawing, points: L.LatLng[], finished: boolean): L.Polyline {
    const p = L.polyline(points, finished ? { ...a.style, renderer: this.historyRenderer } : a.style);
    this.trails.addLayer(p);
    return p;
  }

  /** One point onto the trail's growing piece; a full piece moves to the history canvas and a
   *  new one, joined to it, grows. */
  private addPoint(a: AgentDrawing, p: L.LatLng): void {
    let last = a.pieces[a.pieces.length - 1];
    const points = last ? (last.getLatLngs() as L.LatLng[]) : [];
    if (!last || points.length >= CHUNK_POINTS) {
      if (last) {
        this.trails.removeLayer(last);
        a.pieces[a.pieces.length - 1] = this.piece(a, points, true);
      }
      last = this.piece(a, points.length ? [points[points.length - 1]] : [], false);
      a.pieces.push(last);
    }
    last.addLatLng(p);
  }

  /** The trail's pieces for these points (replacing the old ones). */
  private setPoints(a: AgentDrawing, points: L.LatLng[]): void {
    for (const piece of a.pieces) this.trails.removeLayer(piece);
    a.pieces = [];
    for (let k = 0; k < points.length; k += CHUNK_POINTS - 1) {
      const last = k + CHUNK_POINTS >= points.length;
      a.pieces.push(this.piece(a, points.slice(k, k + CHUNK_POINTS), !last));
      if (last) break;
    }
  }

  /** Draws the trail anew from its rows up to `t` (the timeline dragged, a gap filled:
   *  `gapFill`, counted apart, a trail thinned). */
  rebuildTrail(id: string, rows: TrailRow[], t: number | null = null, gapFill = false): void {
    const a = this.agent(id);
    const points: L.LatLng[] = [];
    a.times = [];
    a.lastX = NaN;
    a.lastY = NaN;
    a.until = -Infinity;
    for (const r of rows) {
      if (t !== null && r[0] > t) break;
      if (this.accept(a, r)) points.push(ll(r[1], r[2]));
    }
    this.setPoints(a, points);
    this.rebuilds++;
    if (gapFill) this.gapFills++;
  }

  /** Whether rows fetched over [first, end] would fill a gap in the drawn trail. */
  hasGap(id: string, first: number, end: number): boolean {
    const times = this.agents.get(id)?.times;
    if (!times || !times.length) return false;
    // Binary search for the first drawn row at or after `first`, then look for a gap up to `end`.
    let lo = 0;
    let hi = times.length;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (times[mid] < first) lo = mid + 1;
      else hi = mid;
    }
    for (let i = Math.max(1, lo); i < times.length && times[i - 1] <= end; i++) {
      if (times[i] - times[i - 1] > GAP_S) return true;
    }
    return false;
  }

  /** Markers, labels and ellipses of the agents shown (cheap: one per agent). */
  updateAgents(agents: NodeState[], selected: string | null, alerted: Set<string>, offFloor: (f?: number) => boolean): void {
    const shown = new Set(agents.map((n) => n.id));
    for (const [id, a] of this.agents) {
      const visible = shown.has(id);
      a.marker.setStyle({ opacity: visible ? 1 : 0, fillOpacity: visible ? 1 : 0 });
      if (!visible) a.ellipse.setLatLngs([]);
    }
    for (const n of agents) {
      const a = this.agent(n.id);
      const off = offFloor(n.floor);
      const sel = n.id === selected;
      a.marker.setLatLng(ll(n.x, n.y));
      a.marker.setRadius(sel ? 8 : 6);
      a.marker.setStyle({
        fillColor: alerted.has(n.id) ? COLOURS.alerted : COLOURS.agent,
        fillOpacity: off ? 0.35 : 1,
        opacity: off ? 0.35 : 1,
        color: sel ? COLOURS.selected : '#ffffff',
      });
      const label = off ? `${n.id} (floor ${n.floor})` : n.id;
      if (a.marker.getTooltip()?.getContent() !== label) a.marker.setTooltipContent(label);
      const e = ellipse95(n.sxx, n.sxy, n.syy);
      const ring: L.LatLng[] = [];
      const c = Math.cos(e.angle);
      const s = Math.sin(e.angle);
      for (let k = 0; k < 36; k++) {
        const th = (2 * Math.PI * k) / 36;
        const u = Math.max(0.05, e.a) * Math.cos(th);
        const v = Math.max(0.05, e.b) * Math.sin(th);
        ring.push(ll(n.x + c * u - s * v, n.y + s * u + c * v));
      }
      a.ellipse.setLatLngs(ring);
      a.ellipse.setStyle({ color: sel ? COLOURS.selected : COLOURS.ellipse, opacity: off ? 0.35 : 1 });
      const style = { color: sel ? COLOURS.selected : COLOURS.trail, weight: sel ? 2.5 : 1.5, opacity: off ? 0.35 : 0.9 };
      if (style.color !== a.style.color || style.weight !== a.style.weight || style.opacity !== a.style.opacity) {
        Object.assign(a.style, style);
        for (const piece of a.pieces) piece.setStyle(style);
      }
    }
    if (this.follow) this.keepInView(agents, selected);
  }

  /** Crumbs, landmarks and the base: a square marker each, with its id. */
  updateStatics(nodes: Array<Pick<NodeState, 'id' | 'kind' | 'x' | 'y' | 'floor'>>, offFloor: (f?: number) => boolean): void {
    for (const n of nodes) {
      let m = this.statics.get(n.id);
      const colour = n.kind === 'base' ? COLOURS.base : n.kind === 'landmark' ? COLOURS.landmark : COLOURS.crumb;
      if (!m) {
        m = L.circleMarker(ll(n.x, n.y), { radius: 4, color: colour, weight: 1, fillColor: colour, fillOpacity: 1, interactive: false });
        m.bindTooltip(n.id, { permanent: true, direction: 'bottom', offset: [0, 4], className: 'node-label' });
        (n.kind === 'base' ? this.bases : n.kind === 'landmark' ? this.landmarks : this.crumbs).addLayer(m);
        this.statics.set(n.id, m);
      }
      m.setLatLng(ll(n.x, n.y));
      const off = offFloor(n.floor);
      m.setStyle({ opacity: off ? 0.3 : 1, fillOpacity: off ? 0.3 : 1 });
    }
  }

  /** The box of the plan (every level) and the given points, for "fit all". */
  fitAll(points: Array<[number, number]>, walls: Wall[]): void {
    const b = L.latLngBounds([]);
    for (const w of walls) b.extend(ll(w[0], w[1])).extend(ll(w[2], w[3]));
    for (const [x, y] of points) if (Number.isFinite(x) && Number.isFinite(y)) b.extend(ll(x, y));
    if (!b.isValid()) return;
    this.map.fitBounds(b.pad(0.05), { animate: false, maxZoom: 5 });
    this.fitted = true;
  }

  /** Fits once, when the first data arrive (later only on the user's request). */
  fitOnce(points: Array<[number, number]>, walls: Wall[]): void {
    if (!this.fitted) this.fitAll(points, walls);
  }

  /** Follow: the selected firefighter, or every firefighter, kept inside the view. */
  private keepInView(agents: NodeState[], selected: string | null): void {
    const targets = selected ? agents.filter((n) => n.id === selected) : agents;
    if (!targets.length) return;
    const b = L.latLngBounds(targets.map((n) => ll(n.x, n.y)));
    if (this.map.getBounds().pad(-0.1).contains(b)) return;
    if (targets.length === 1) this.map.panTo(b.getCenter(), { animate: false });
    else this.map.fitBounds(b.pad(0.3), { animate: false, maxZoom: this.map.getZoom() });
  }

  stats(): MapStats {
    const zoom = this.map.getZoom();
    return {
      appends: this.appends,
      rebuilds: this.rebuilds,
      gapFills: this.gapFills,
      planLevel: this.shownLevel,
      planSegments: this.planSegments,
      zoom,
      scale: this.map.getZoomScale(zoom, 0),
      center: [this.map.getCenter().lng, this.map.getCenter().lat],
      touchZoom: this.map.touchZoom.enabled(),
    };
  }

  /** The trail as drawn (points; the pieces' shared joints counted once), for the tests. */
  trailPoints(id: string): number {
    const a = this.agents.get(id);
    if (!a) return 0;
    let n = 0;
    a.pieces.forEach((p, k) => (n += (p.getLatLngs() as L.LatLng[]).length - (k > 0 ? 1 : 0)));
    return n;
  }

  invalidateSize(): void {
    this.map.invalidateSize({ animate: false });
  }
}
