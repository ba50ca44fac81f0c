// The progress curve of a job in a 2D canvas: every solve at (time since the job started, λ),
// accepted or rejected, and the λ reached so far as a staircase.

const COLORS = {
  background: '#ffffff',
  grid: '#e6eaee',
  axis: '#66717d',
  text: '#3e4c59',
  accepted: '#2f6fb0',
  rejected: '#d64541',
  reached: '#2e7d4f',
  tutor: '#8a96a3',
};
const MARGIN = { left: 46, right: 14, top: 12, bottom: 36 };

/** Time of each point since the job started: the extrapolation's clock starts after the tutor. */
export function jobTimes(points) {
  const tutor = points.filter((p) => p.phase === 'tutor');
  const offset = tutor.length ? Math.max(...tutor.map((p) => p.wall_time)) : 0;
  return points.map((p) => (p.phase === 'tutor' ? p.wall_time : p.wall_time + offset));
}

/** A round step giving about `n` ticks over [0, max]. */
function tickStep(max, n = 6) {
  const raw = max / n;
  const mag = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw);
}

/**
 * Draws `points` (the job's `progress` records) into `canvas`, sized to its CSS box.
 * Returns the number of solves drawn.
 */
export function drawProgress(canvas, points) {
  const dpr = window.devicePixelRatio || 1;
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (!w || !h) return 0;
  canvas.width = Math.round(w * dpr);
  canvas.height = Math.round(h * dpr);
  const ctx = canvas.getContext('2d');
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  ctx.fillStyle = COLORS.background;
  ctx.fillRect(0, 0, w, h);

  const times = jobTimes(points);
  const tmax = Math.max(1, ...times) * 1.04;
  const pw = w - MARGIN.left - MARGIN.right, ph = h - MARGIN.top - MARGIN.bottom;
  const x = (t) => MARGIN.left + (t / tmax) * pw;
  const y = (lam) => MARGIN.top + (1 - lam) * ph;

  // grid, ticks, labels
  ctx.font = '11px system-ui, sans-serif';
  ctx.lineWidth = 1;
  ctx.fillStyle = COLORS.text;
  ctx.textAlign = 'right';
  ctx.textBaseline = 'middle';
  for (const lam of [0, 0.25, 0.5, 0.75, 1]) {
    ctx.strokeStyle = COLORS.grid;
    ctx.beginPath(); ctx.moveTo(MARGIN.left, y(lam)); ctx.lineTo(w - MARGIN.right, y(lam)); ctx.stroke();
    ctx.fillText(String(lam), MARGIN.left - 6, y(lam));
  }
  const step = tickStep(tmax);
  ctx.textAlign = 'center';
  ctx.textBaseline = 'top';
  for (let t = 0; t <= tmax + 1e-9; t += step) {
    ctx.strokeStyle = COLORS.grid;
    ctx.beginPath(); ctx.moveTo(x(t), MARGIN.top); ctx.lineTo(x(t), h - MARGIN.bottom); ctx.stroke();
    ctx.fillText(String(+t.toFixed(3)), x(t), h - MARGIN.bottom + 5);
  }
  ctx.strokeStyle = COLORS.axis;
  ctx.beginPath();
  ctx.moveTo(MARGIN.left, MARGIN.top); ctx.lineTo(MARGIN.left, h - MARGIN.bottom); ctx.lineTo(w - MARGIN.right, h - MARGIN.bottom);
  ctx.stroke();
  ctx.fillText('time since the job started (s)', MARGIN.left + pw / 2, h - 16);
  ctx.save();
  ctx.translate(13, MARGIN.top + ph / 2);
  ctx.rotate(-Math.PI / 2);
  ctx.textBaseline = 'middle';
  ctx.font = 'italic 13px system-ui, sans-serif';
  ctx.fillText('λ', 0, 0);
  ctx.restore();

  if (!points.length) {
    ctx.fillStyle = COLORS.axis;
    ctx.textBaseline = 'middle';
    ctx.fillText('waiting for the first solve…', MARGIN.left + pw / 2, MARGIN.top + ph / 2);
    return 0;
  }

  // λ reached: a staircase through the solves
  ctx.strokeStyle = COLORS.reached;
  ctx.lineWidth = 2;
  ctx.beginPath();
  points.forEach((p, i) => {
    if (i === 0) ctx.moveTo(x(times[i]), y(p.lam_reached));
    else { ctx.lineTo(x(times[i]), y(points[i - 1].lam_reached)); ctx.lineTo(x(times[i]), y(p.lam_reached)); }
  });
  ctx.stroke();

  // the solves
  ctx.lineWidth = 2;
  points.forEach((p, i) => {
    const px = x(times[i]), py = y(p.lam);
    if (p.phase === 'tutor') {
      ctx.fillStyle = COLORS.tutor;
      ctx.fillRect(px - 4, py - 4, 8, 8);
    } else if (p.accepted) {
      ctx.fillStyle = COLORS.accepted;
      ctx.beginPath(); ctx.arc(px, py, 4.5, 0, 2 * Math.PI); ctx.fill();
    } else {
      ctx.strokeStyle = COLORS.rejected;
      ctx.beginPath();
      ctx.moveTo(px - 4, py - 4); ctx.lineTo(px + 4, py + 4);
      ctx.moveTo(px + 4, py - 4); ctx.lineTo(px - 4, py + 4);
      ctx.stroke();
    }
  });
  return points.length;
}
