// The assembly the server runs, as the Session keeps it (`state.assembly`), no DOM: built from
// `assembly_planned` (or a late joiner's `state`), moved on by each move's start and end, a
// filled site and a new plan, closed by `assembly_done`. SI, as the messages have it; the plan
// names particles by their index in its map. What a site shows now (`siteState`) is read from
// it. Each reducer returns the Session's event `{kind: 'assembly', what, assembly}`.

/** An assembly as its first plan, or a `state`'s `assembly`, describes it. */
function fresh(m) {
  return {
    id: m.assembly,
    by: m.by ?? null,
    planOnly: !!m.plan_only,
    pattern: m.pattern ?? '',
    sites: Array.isArray(m.sites) ? m.sites : [],
    phase: 'planning',
    plan: m.plan ?? null,
    frame: typeof m.frame === 'string' && m.frame ? m.frame : null, // the full frame it was planned on
    made: [], // each move made: proto's MoveSummary
    filled: [], // the sites the scans after the moves showed filled
    moving: null, // [the move running, from 1, the moves planned in all]
    current: null, // the move running, as planned (its path)
    particleId: null, // its particle's scene id
    done: null, // {outcome, reason, summary, record, record_error}
  };
}

const ev = (what, a) => ({ kind: 'assembly', what, assembly: a });

/** The assembly a message is about, when it is the one this page knows. */
function known(s, m) {
  return s.assembly && s.assembly.id === m.assembly ? s.assembly : null;
}

export function planned(s, m) {
  s.assembly = fresh(m);
  s.assembly.phase = m.plan_only ? 'planned' : 'moving';
  return ev('planned', s.assembly);
}

export function moveStarted(s, m) {
  const a = known(s, m);
  if (!a) return ev('stray', null);
  a.phase = 'moving';
  a.moving = [m.number, m.of];
  a.current = m.planned ?? null;
  a.particleId = m.particle_id ?? null;
  return ev('move_started', a);
}

export function moveEnded(s, m) {
  const a = known(s, m);
  if (!a) return ev('stray', null);
  if (m.made) a.made.push(m.made);
  a.phase = 'replanning';
  a.moving = null;
  a.current = null;
  return ev('move_ended', a);
}

export function siteFilled(s, m) {
  const a = known(s, m);
  if (!a) return ev('stray', null);
  if (!a.filled.includes(m.site)) a.filled.push(m.site);
  return ev('site_filled', a);
}

export function replanned(s, m) {
  const a = known(s, m);
  if (!a) return ev('stray', null);
  a.plan = m.plan ?? a.plan;
  return ev('replanned', a);
}

/** The end. An assembly this page never saw start (the report alone) is taken from its summary. */
export function done(s, m) {
  let a = known(s, m);
  if (!a) {
    const sites = (m.summary?.sites ?? []).map((x) => ({ target: x.target, tolerance: x.tolerance }));
    a = fresh({ assembly: m.assembly, pattern: m.summary?.pattern, sites });
    s.assembly = a;
  }
  a.phase = 'done';
  a.moving = null;
  a.current = null;
  a.done = { outcome: m.outcome, reason: m.reason ?? null, summary: m.summary ?? null, record: m.record ?? null, record_error: m.record_error ?? null };
  return ev('done', a);
}

/**
 * A `state`'s `assembly` (null: none runs). A running one replaces what the page knew (it may
 * have missed events); none running leaves a finished one shown, and marks one this page saw
 * running as ended unseen (it ended while the page was away: its record tells how).
 */
export function fromState(s, now) {
  if (now) {
    const a = fresh(now);
    a.phase = now.phase ?? 'moving';
    a.made = Array.isArray(now.moves) ? [...now.moves] : [];
    a.filled = Array.isArray(now.filled) ? [...now.filled] : [];
    a.moving = Array.isArray(now.moving) ? now.moving : null;
    // The plan's moves are those still to make: the one running is its first.
    a.current = a.moving ? a.plan?.moves?.[0] ?? null : null;
    s.assembly = a;
    return true;
  }
  const a = s.assembly;
  if (a && !a.done) {
    a.phase = 'done';
    a.moving = null;
    a.current = null;
    a.done = { outcome: 'unseen', reason: null, summary: null, record: null, record_error: null };
    return true;
  }
  return false;
}

/**
 * What site `i` shows now: {state, reason}. `state` is `filled`, `planned` (a move of the plan
 * fills it), `missed`, `unreachable`, `refused` or `open` (no plan yet); the final report's
 * word once there is one.
 */
export function siteState(a, i) {
  const end = a.done?.summary?.sites?.[i];
  if (end) return { state: end.status, reason: end.reason ?? null };
  if (a.filled.includes(i)) return { state: 'filled', reason: null };
  const p = a.plan?.sites?.[i];
  if (!p) return { state: 'open', reason: null };
  if (p.state === 'filled' || p.state === 'planned') return { state: p.state, reason: null };
  return { state: p.status ?? 'open', reason: p.reason ?? null };
}
