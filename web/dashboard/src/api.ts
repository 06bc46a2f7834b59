// SPDX-License-Identifier: MIT
// The server's JSON contract (docs/server.md): GET /api/state, /api/history, /api/floorplan and
// the server-sent events of /api/events (each message: the state).

export interface NodeState {
  id: string;
  kind: 'agent' | 'crumb' | 'landmark' | 'base';
  t: number;
  x: number;
  y: number;
  z: number;
  sxx: number;
  sxy: number;
  syy: number;
  /** The level the estimator believes (mission format 1.1); absent when it gives none. */
  floor?: number;
  /** Vertical variance, m². */
  szz?: number;
  /** The fusion: which sources (member pipelines) the estimate uses, with their shares. */
  sources?: Array<{ source: string; weight: number }>;
}

export interface Alert {
  id: string;
  kind: string; // no-data, motionless, uncertainty, map-error, device-lost
  t: number;
  message: string;
}

export interface State {
  t: number | null;
  nodes: NodeState[];
  alerts: Alert[];
}

/** Rows [t, x, y, sxx, sxy, syy] of each agent, oldest first. */
/** t, x, y, sxx, sxy, syy, floor (null where the estimator gives none). */
export type TrailRow = [number, number, number, number, number, number, (number | null)?];

export interface History {
  t: number | null;
  /** Present when only the part after this mission time was asked for. */
  since?: number;
  trails: Record<string, TrailRow[]>;
  alerts: Alert[];
}

export type Wall = [number, number, number, number];

/** A node known a priori (mission.json `position`): the base, surveyed landmarks. */
export interface KnownNode {
  id: string;
  kind: NodeState['kind'];
  x: number;
  y: number;
}

/** One level's walls of a multi-level plan. */
export interface LevelWalls {
  level: number;
  walls: Wall[];
}

export interface FloorPlan {
  walls: Wall[];
  nodes: KnownNode[];
  /** A multi-level plan: the level of `walls`, and every level's walls. */
  level?: number;
  levels?: LevelWalls[];
}

export class Api {
  constructor(private readonly token: string) {}

  private async get<T>(path: string): Promise<T> {
    const r = await fetch(path, { headers: { Authorization: `Bearer ${this.token}` } });
    if (!r.ok) throw new Error(`${path}: HTTP ${r.status}`);
    return (await r.json()) as T;
  }

  state(): Promise<State> {
    return this.get<State>('/api/state');
  }
  /** The whole history, or (`since`) only what came after that mission time. */
  history(since?: number): Promise<History> {
    return this.get<History>(since === undefined ? '/api/history' : `/api/history?since=${since}`);
  }
  floorPlan(): Promise<FloorPlan> {
    return this.get<FloorPlan>('/api/floorplan');
  }
  /** Live states; `onState` for each message, `onStatus` for the connection. */
  events(onState: (s: State) => void, onStatus: (ok: boolean) => void): EventSource {
    const es = new EventSource(`/api/events?token=${encodeURIComponent(this.token)}`);
    es.onmessage = (m) => onState(JSON.parse(m.data) as State);
    es.onopen = () => onStatus(true);
    es.onerror = () => onStatus(false); // EventSource reconnects by itself
    return es;
  }
}
