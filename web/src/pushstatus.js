// What runs now and how the last push ended, under Stop: the push running (everyone's view of it:
// who pushes which particle where, and its progress against the plan: the particle's travel so
// far of the planned distance, a bar, and the pushing time left at the scene's push speed), a
// push whose end this page did not see (the connection closed while it ran: its outcome is
// unknown until the server is back), else the last run's outcome in its colour. One of them at a
// time, in a box that keeps its height, so the forms below never move. The texts and the
// progress are pure (Node tests); PushStatus writes them into the page, the progress at most 5
// times a second.
import { formatStagePoint } from './format.js';
import { pusher } from './eventlog.js';
import { phaseWords } from './words.js';

/** The length of a path (m): the sum of its legs. */
export function pathLength(path) {
  let L = 0;
  for (let k = 1; k < (path?.length ?? 0); k++) L += Math.hypot(path[k][0] - path[k - 1][0], path[k][1] - path[k - 1][1]);
  return L;
}

/**
 * How far along `path` (m) the point `p` is: the distance from the path's start to the point of
 * the path nearest `p`, measured along the path. An estimate off the path counts where it is
 * abreast of.
 */
export function travelAlong(path, p) {
  if (!Array.isArray(path) || path.length < 2 || !p) return 0;
  let best = Infinity;
  let along = 0;
  let before = 0;
  for (let k = 1; k < path.length; k++) {
    const [ax, ay] = path[k - 1];
    const dx = path[k][0] - ax;
    const dy = path[k][1] - ay;
    const len2 = dx * dx + dy * dy;
    const f = len2 > 0 ? Math.min(1, Math.max(0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / len2)) : 0;
    const d = Math.hypot(ax + f * dx - p[0], ay + f * dy - p[1]);
    if (d < best) {
      best = d;
      along = before + f * Math.sqrt(len2);
    }
    before += Math.sqrt(len2);
  }
  return along;
}

/**
 * A push's progress against its plan: `doneM` of `totalM` (m) travelled by the particle (its
 * live estimate along the path; 0 before the estimate comes), and `leftS`, the pushing time left
 * at `speedMps` (null when the speed is unknown).
 */
export function pushProgress(push, estimate, speedMps) {
  const totalM = pathLength(push.path);
  const doneM = Math.min(totalM, travelAlong(push.path, estimate));
  const leftS = speedMps > 0 ? (totalM - doneM) / speedMps : null;
  return { doneM, totalM, leftS };
}

/** The progress in words: `2.10 of 5.00 µm · about 2 s of pushing left · pushing`. */
export function progressText(pr, phase) {
  const um = (m) => (m * 1e6).toFixed(2);
  const left = pr.leftS === null ? '' : pr.leftS >= 0.5 ? ` · about ${Math.ceil(pr.leftS)} s of pushing left` : ' · pushed';
  return `${um(pr.doneM)} of ${um(pr.totalM)} µm${left}${phase ? ` · ${phaseWords(phase)}` : ''}`;
}

/** The headline of the push running: `Pushing #1 (you) to (45.000, 32.500) µm`. */
export function pushNowText(push, client) {
  return `Pushing #${push.particle} (${pusher(push, client)}) to ${formatStagePoint(push.path[push.path.length - 1])}`;
}

/** A push that ran when the connection closed: what is known of it while the server is away. */
export function lostNowText(lost, client) {
  return `Push of #${lost.particle} (${pusher(lost, client)}): outcome unknown until the server is back (the connection closed while it ran)`;
}

export class PushStatus {
  /**
   * @param {(id: string) => HTMLElement} $ the page's elements by id
   * @param {import('./frame.js').FrameScheduler} scheduler
   * @param {{state: () => object, speed: () => number | null}} deps the Session's state and the
   *   scene's push speed (m/s)
   */
  constructor($, scheduler, { state, speed }) {
    this.$ = $;
    this.state = state;
    this.speed = speed;
    this.version = 0; // bumped by every change of the last run's line
    this.lostClient = null; // this page's client id when the connection closed
    this.frame = scheduler.register('pushstatus', () => this.renderProgress(), { period: 200, aligned: true });
  }

  /** The connection closed: remember who this page was, to say "you" of a push it ran. */
  closed(client) {
    this.lostClient = client;
    this.render();
  }

  /** Shows the push running, or the one lost with the connection, or else the last run. */
  render() {
    const $ = this.$;
    const st = this.state();
    const box = $('push-now');
    const p = st.push;
    const lost = !p && st.lostPush && st.connection !== 'open' ? st.lostPush : null;
    if (p) {
      $('push-now-text').textContent = pushNowText(p, st.client);
      box.className = 'push-now';
      $('push-bar').hidden = false;
      this.renderProgress();
    } else if (lost) {
      $('push-now-text').textContent = lostNowText(lost, this.lostClient);
      box.className = 'push-now unknown';
      $('push-bar').hidden = true;
      $('push-progress').textContent = '';
    }
    box.hidden = !p && !lost;
    $('lastrun').hidden = !box.hidden || !$('lastrun').textContent;
  }

  /** The progress of the push running: in the next frame, at most 5 times a second. */
  progressed() {
    if (this.state().push) this.frame.mark();
  }

  renderProgress() {
    const st = this.state();
    if (!st.push) return;
    const pr = pushProgress(st.push, st.tip?.estimate ?? null, this.speed());
    const bar = this.$('push-bar');
    bar.max = pr.totalM > 0 ? pr.totalM * 1e6 : 1;
    bar.value = pr.doneM * 1e6;
    this.$('push-progress').textContent = progressText(pr, st.connection === 'open' ? st.phase : null);
  }

  /** The last run's line: `cls` good, neutral, warn, bad or unknown. */
  showRun(text, cls) {
    this.version++;
    const el = this.$('lastrun');
    el.textContent = text;
    el.className = `lastrun ${cls}`;
    this.render();
  }

  /** The server restarted: the last run shown was the previous server's. */
  clearRun() {
    this.version++;
    this.$('lastrun').textContent = '';
    this.render();
  }
}
