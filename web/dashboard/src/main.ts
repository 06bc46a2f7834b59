// SPDX-License-Identifier: MIT
// The incident commander's dashboard: floor plan, every firefighter with position, 95 % ellipse,
// trail and name; crumbs, landmarks, the base; status and alerts per firefighter; a timeline
// to scrub back; in a multi-level building a floor selector draws one level's plan (the
// selected firefighter's floor when picked), nodes on other floors dimmed with their floor. Live
// through server-sent events; history from /api/history. The map (map.ts) is Leaflet's: pan,
// zoom, pinch, a scale bar, layers; "fit all" and "follow" as buttons.
import './style.css';
import { Api, type Alert, type History, type KnownNode, type LevelWalls, type NodeState, type State, type TrailRow, type Wall } from './api';
import { Bounds, ellipse95, rowAt, thinTrail } from './geometry';
import { IncidentMap, type MapStats } from './map';

const token = new URLSearchParams(location.search).get('token') ?? '';
const api = new Api(token);
const $ = <T extends HTMLElement>(id: string) => document.getElementById(id) as T;
const timeline = $<HTMLInputElement>('timeline');
const liveButton = $<HTMLButtonElement>('live');
const floorSelect = $<HTMLSelectElement>('floor');
const fitButton = $<HTMLButtonElement>('fit');
const followButton = $<HTMLButtonElement>('follow');
const incidentMap = new IncidentMap($('map'), (id) => select(id));

let walls: Wall[] = [];
let levels: LevelWalls[] = [];
let shownLevel: number | null = null; // null: a single-level plan
let known: KnownNode[] = [];
let live: State = { t: null, nodes: [], alerts: [] };
let trails: Record<string, TrailRow[]> = {};
const trailBounds = new Bounds(); // every trail row's extent, kept as rows arrive
let alertLog: Alert[] = [];
let following = true; // the timeline follows the incident
let selected: string | null = null;
const TRAIL_PERIOD_S = 0.5;
// A trail's rows in memory: at most this many; the last ten minutes (at TRAIL_PERIOD_S) whole.
const MAX_TRAIL_ROWS = 2400;
const KEEP_RECENT_ROWS = 1200;

/** Thins a long trail (memory and drawing stay bounded over a whole incident). */
function boundTrail(id: string): void {
  const thinned = thinTrail(trails[id], MAX_TRAIL_ROWS, KEEP_RECENT_ROWS);
  if (!thinned) return;
  trails[id] = thinned;
  if (following) incidentMap.rebuildTrail(id, thinned);
}

const ALERT_LABEL: Record<string, string> = {
  'no-data': 'LINK LOST',
  motionless: 'MOTIONLESS',
  uncertainty: 'UNCERTAIN',
  'map-error': 'MAP ERROR',
  'device-lost': 'DEVICE LOST',
  integrity: 'INTEGRITY',
};

/** Merges a history (whole, or the part after `since`) into the trails and the alert log:
 *  each trail keeps its rows before the fetched ones, then the fetched rows, then what came
 *  live after them. */
function mergeHistory(h: History): void {
  for (const [id, rows] of Object.entries(h.trails)) {
    if (!rows.length) continue;
    const first = rows[0][0];
    const end = rows[rows.length - 1][0];
    const gap = incidentMap.hasGap(id, first, end); // rows that fill a gap: redraw that trail
    const old = trails[id] ?? [];
    trails[id] = old.filter((r) => r[0] < first).concat(rows, old.filter((r) => r[0] > end));
    for (const r of rows) trailBounds.add(r[1], r[2]);
    if (following) {
      if (gap) incidentMap.rebuildTrail(id, trails[id], null, true);
      else incidentMap.appendTrail(id, rows);
    } // else the timeline shows the past: drawn when it returns
    boundTrail(id);
  }
  if (h.t !== null) historyEnd = Math.max(historyEnd ?? -Infinity, h.t);
  if (h.since === undefined) {
    alertLog = h.alerts;
  } else {
    for (const a of h.alerts) {
      if (!alertLog.some((b) => b.id === a.id && b.kind === a.kind && b.t === a.t)) alertLog.push(a);
    }
  }
}

/** The mission time the periodic refresh asks from: a little before the end of the last
 *  history fetched (what came live since may have gaps: a lost connection), the whole history
 *  before any. */
let historyEnd: number | undefined;
function refreshSince(): number | undefined {
  return historyEnd === undefined ? undefined : historyEnd - 5;
}

function onState(s: State): void {
  live = s;
  for (const n of s.nodes) {
    if (n.kind !== 'agent') continue;
    const trail = (trails[n.id] ??= []);
    const last = trail[trail.length - 1];
    if (!last || n.t >= last[0] + TRAIL_PERIOD_S) {
      const row: TrailRow = [n.t, n.x, n.y, n.sxx, n.sxy, n.syy, n.floor ?? null];
      trail.push(row);
      trailBounds.add(n.x, n.y);
      if (following) incidentMap.appendTrail(n.id, [row]);
      boundTrail(n.id);
    }
  }
  for (const a of s.alerts) {
    if (!alertLog.some((b) => b.id === a.id && b.kind === a.kind && Math.abs(b.t - a.t) < 60)) alertLog.push(a);
  }
  updateTimeline();
  scheduleRender();
}

// At most one redraw per animation frame: live messages come up to 100 a second.
let renderPending = false;
function scheduleRender(): void {
  if (renderPending) return;
  renderPending = true;
  requestAnimationFrame(() => {
    renderPending = false;
    render();
  });
}

/** The time shown: the live clock, or where the timeline was dragged. */
function shownTime(): number | null {
  if (following) return live.t;
  return Number(timeline.value);
}

function timeRange(): [number, number] | null {
  let t0 = Infinity;
  for (const rows of Object.values(trails)) if (rows.length) t0 = Math.min(t0, rows[0][0]);
  if (live.t === null || !Number.isFinite(t0)) return null;
  return [t0, Math.max(t0, live.t)];
}

function updateTimeline(): void {
  const r = timeRange();
  if (!r) return;
  timeline.min = String(r[0]);
  timeline.max = String(r[1]);
  if (following) timeline.value = String(r[1]);
}

/** Agents at time t: the live state when following, else the trails. */
function agentsAt(t: number | null): NodeState[] {
  const agents = live.nodes.filter((n) => n.kind === 'agent');
  if (following || t === null) return agents;
  const out: NodeState[] = [];
  for (const [id, rows] of Object.entries(trails)) {
    const r = rowAt(rows, t);
    if (r) out.push({ id, kind: 'agent', t: r[0], x: r[1], y: r[2], z: 0, sxx: r[3], sxy: r[4], syy: r[5], floor: r[6] ?? undefined });
  }
  return out.sort((a, b) => a.id.localeCompare(b.id));
}

/** Alerts active at t: live ones, or those raised within the minute before t when scrubbing. */
function alertsAt(t: number | null): Alert[] {
  if (following || t === null) return live.alerts;
  return alertLog.filter((a) => a.t <= t && a.t > t - 60);
}

/** Whether a node is known to be on another floor than the one shown. */
function offFloor(floor: number | undefined): boolean {
  return shownLevel !== null && floor !== undefined && floor !== shownLevel;
}

function showLevel(level: number): void {
  if (shownLevel === null || !levels.some((l) => l.level === level)) return;
  shownLevel = level;
  floorSelect.value = String(level);
  incidentMap.showLevel(level);
}

function setUpFloors(plan: { level?: number; levels?: LevelWalls[] }): void {
  levels = (plan.levels ?? []).slice().sort((a, b) => a.level - b.level);
  if (levels.length < 2) return;
  shownLevel = plan.level ?? levels[0].level;
  floorSelect.replaceChildren(
    ...levels
      .slice()
      .reverse()
      .map((l) => {
        const o = document.createElement('option');
        o.value = String(l.level);
        o.textContent = String(l.level);
        return o;
      }),
  );
  floorSelect.value = String(shownLevel);
  $('floorbar').hidden = false;
}

/** Every trail drawn anew: to the time shown while the timeline is dragged, whole when live. */
function redrawTrails(): void {
  const t = following ? null : shownTime();
  for (const [id, rows] of Object.entries(trails)) incidentMap.rebuildTrail(id, rows, t);
}

/** The nodes' positions and the corners of the trails' box (not their every row): what
 *  "fit all" shows besides the walls. */
function fitPoints(nodes: Array<Pick<NodeState, 'x' | 'y'>>): Array<[number, number]> {
  const points: Array<[number, number]> = nodes.map((n) => [n.x, n.y]);
  const xs: number[] = [];
  const ys: number[] = [];
  trailBounds.corners(xs, ys);
  xs.forEach((x, i) => points.push([x, ys[i] ?? x]));
  return points;
}

/** Every wall of every level, for "fit all". */
function allWalls(): Wall[] {
  return levels.length ? levels.flatMap((l) => l.walls) : walls;
}

function render(): void {
  const t = shownTime();
  const agents = agentsAt(t);
  const alerts = alertsAt(t);
  const estimated = live.nodes.filter((n) => n.kind !== 'agent');
  // known nodes (the base, surveyed landmarks) where no estimate replaces them
  const others: Array<Pick<NodeState, 'id' | 'kind' | 'x' | 'y' | 'floor'>> = [
    ...estimated,
    ...known.filter((k) => !estimated.some((n) => n.id === k.id)),
  ];
  const alerted = new Set(alerts.map((a) => a.id));
  incidentMap.updateStatics(others, offFloor);
  incidentMap.updateAgents(agents, selected, alerted, offFloor);
  if (agents.length) incidentMap.fitOnce(fitPoints([...agents, ...others]), allWalls());
  const stats: MapStats & { trailPoints?: (id: string) => number } = incidentMap.stats();
  stats.trailPoints = (id: string) => incidentMap.trailPoints(id);
  // For the browser tests: the view's scale (px/m), the plan drawn, appends and rebuilds.
  (window as unknown as { trailmarkView?: { scale: number } }).trailmarkView = { scale: stats.scale };
  (window as unknown as { trailmarkMap?: typeof stats }).trailmarkMap = stats;
  renderSide(agents, alerts, t);
}

// One element per firefighter, kept across renders and updated in place: the list is redrawn on
// every server-sent message (up to 100 a second), and an element replaced between a press and its
// release swallows the click. Each entry is a button, so the keyboard reaches it (Tab, Enter).
const listEntries = new Map<string, HTMLButtonElement>();

/** One list entry per firefighter, made once: its name, ellipse and badge elements are kept and
 *  only their text changes, so the element under the pointer is never replaced between a
 *  mousedown and its mouseup (Chromium drops the click when the pressed node left the page —
 *  a live message arrives every few milliseconds). */
function listEntry(id: string): HTMLButtonElement {
  let entry = listEntries.get(id);
  if (!entry) {
    entry = document.createElement('button');
    entry.type = 'button';
    entry.className = 'node';
    entry.dataset.id = id;
    entry.onclick = () => select(id);
    const name = document.createElement('span');
    name.className = 'pos';
    const detail = document.createElement('small');
    const badges = document.createElement('span');
    badges.className = 'badges';
    entry.append(name, detail, badges);
    listEntries.set(id, entry);
  }
  return entry;
}

function setText(el: Element, text: string): void {
  if (el.textContent !== text) el.textContent = text;
}

/** The fusion's sources of an estimate, largest share first: " · beacons-ekf 80 %, mapmatch 20 %". */
function sourcesText(n: NodeState): string {
  const shown = (n.sources ?? []).filter((s) => s.weight >= 0.05).sort((a, b) => b.weight - a.weight);
  if (shown.length === 0) return '';
  return ` · ${shown.map((s) => `${s.source} ${Math.round(100 * s.weight)} %`).join(', ')}`;
}

function renderSide(agents: NodeState[], alerts: Alert[], t: number | null): void {
  const list = $('list');
  const shownIds = new Set(agents.map((n) => n.id));
  for (const [id, entry] of listEntries) {
    if (!shownIds.has(id)) (entry.remove(), listEntries.delete(id));
  }
  agents.forEach((n, index) => {
    const entry = listEntry(n.id);
    entry.classList.toggle('sel', n.id === selected);
    entry.setAttribute('aria-pressed', String(n.id === selected));
    const [name, detail, badgeBox] = Array.from(entry.children) as HTMLElement[];
    setText(name, `${n.id}: (${n.x.toFixed(1)}, ${n.y.toFixed(1)}) m`);
    const level = n.floor === undefined ? '' : `, floor ${n.floor}`;
    setText(detail, ` ±${ellipse95(n.sxx, n.sxy, n.syy).a.toFixed(1)} m${level}${sourcesText(n)}`);
    const mine = alerts.filter((x) => x.id === n.id);
    const badgeKey = mine.map((a) => a.kind).join('|');
    if (badgeBox.dataset.key !== badgeKey) {
      badgeBox.dataset.key = badgeKey;
      badgeBox.replaceChildren(
        ...mine.map((a) => {
          const badge = document.createElement('span');
          badge.className = `badge ${a.kind}`;
          badge.textContent = ALERT_LABEL[a.kind] ?? a.kind;
          return badge;
        }),
      );
    }
    if (list.children[index] !== entry) list.insertBefore(entry, list.children[index] ?? null);
  });
  // The alert log is a live region: rewritten only when the alerts change, so a screen reader
  // announces a new alert once instead of the whole list on every message.
  const alertKey = alerts.map((a) => `${a.kind}|${a.id}|${a.t.toFixed(0)}|${a.message}`).join('\n');
  const alertLog = $('alerts');
  if (alertLog.dataset.key !== alertKey) {
    alertLog.dataset.key = alertKey;
    alertLog.replaceChildren(
      ...alerts.map((a) => {
        const div = document.createElement('div');
        div.className = `alert ${a.kind}`;
        div.dataset.kind = a.kind;
        div.textContent = `${a.t.toFixed(0)} s — ${a.message}`;
        return div;
      }),
    );
  }
  $('clock').textContent = t === null ? 'waiting for data…' : `${following ? 'live' : 'replay'} — mission time ${t.toFixed(1)} s`;
}

function select(id: string): void {
  selected = selected === id ? null : id;
  // Picking a firefighter shows the floor it is on.
  const floor = agentsAt(shownTime()).find((n) => n.id === selected)?.floor;
  if (selected !== null && floor !== undefined) showLevel(floor);
  render();
}

timeline.addEventListener('input', () => {
  following = Number(timeline.value) >= Number(timeline.max) - 1e-6;
  liveButton.classList.toggle('on', following);
  redrawTrails();
  render();
});
floorSelect.addEventListener('change', () => {
  showLevel(Number(floorSelect.value));
  render();
});
liveButton.addEventListener('click', () => {
  const was = following;
  following = true;
  liveButton.classList.add('on');
  updateTimeline();
  if (!was) redrawTrails();
  render();
});
fitButton.addEventListener('click', () => incidentMap.fitAll(fitPoints(live.nodes), allWalls()));
followButton.addEventListener('click', () => {
  incidentMap.follow = !incidentMap.follow;
  followButton.setAttribute('aria-pressed', String(incidentMap.follow));
  followButton.classList.toggle('on', incidentMap.follow);
  render();
});
window.addEventListener('resize', () => {
  incidentMap.invalidateSize();
  render();
});

async function start(): Promise<void> {
  try {
    const plan = await api.floorPlan();
    walls = plan.walls;
    known = plan.nodes;
    setUpFloors(plan);
    incidentMap.setPlan(walls, levels, shownLevel);
    mergeHistory(await api.history());
    onState(await api.state());
  } catch (e) {
    $('conn').textContent = `not authorized or server unreachable (${(e as Error).message})`;
    return;
  }
  api.events(onState, (ok) => {
    $('conn').textContent = ok ? 'connected (live)' : 'connection lost — reconnecting…';
    $('conn').className = ok ? 'muted' : 'warn';
  });
  // The history catches up what a reconnect missed.
  setInterval(() => void api.history(refreshSince()).then(mergeHistory).catch(() => undefined), 10000);
}

void start();
