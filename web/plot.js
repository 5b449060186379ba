// Small plots on a 2-D canvas: curves (optionally on a log x axis), the eigenvalue staircase against Weyl's law,
// and a matrix as a heat map. No library: axes, ticks and labels drawn here.
import { rampCss } from './render.js';

function setup(canvas) {
  const w = canvas.clientWidth, h = canvas.clientHeight, r = devicePixelRatio;
  canvas.width = Math.round(w * r);
  canvas.height = Math.round(h * r);
  const g = canvas.getContext('2d');
  g.setTransform(r, 0, 0, r, 0, 0);
  g.clearRect(0, 0, w, h);
  g.font = '11px system-ui, sans-serif';
  return { g, w, h };
}

function nice(x) {
  if (!isFinite(x)) return String(x);
  const a = Math.abs(x);
  return a !== 0 && (a < 1e-2 || a >= 1e4) ? x.toExponential(1) : String(Math.round(x * 100) / 100);
}

// series: [{ xs, ys, colour, step, label }]; options: { logx, xlabel, ylabel }
export function plotCurves(canvas, series, options = {}) {
  const { g, w, h } = setup(canvas);
  const m = { l: 48, r: 10, t: 10, b: 30 };
  const fx = options.logx ? Math.log10 : (x) => x;
  const pts = series.flatMap((s) => s.xs.map((x, i) => [fx(x), s.ys[i]])).filter(([x, y]) => isFinite(x) && isFinite(y));
  if (!pts.length) return;
  const [x0, x1] = [Math.min(...pts.map((p) => p[0])), Math.max(...pts.map((p) => p[0]))];
  const [y0, y1] = [Math.min(0, ...pts.map((p) => p[1])), Math.max(...pts.map((p) => p[1]))];
  const X = (x) => m.l + ((fx(x) - x0) / (x1 - x0 || 1)) * (w - m.l - m.r);
  const Y = (y) => h - m.b - ((y - y0) / (y1 - y0 || 1)) * (h - m.t - m.b);
  g.strokeStyle = '#888';
  g.fillStyle = '#333';
  g.beginPath();
  g.moveTo(m.l, m.t);
  g.lineTo(m.l, h - m.b);
  g.lineTo(w - m.r, h - m.b);
  g.stroke();
  for (let i = 0; i <= 4; i++) {
    const xv = x0 + ((x1 - x0) * i) / 4, yv = y0 + ((y1 - y0) * i) / 4;
    const xl = options.logx ? nice(10 ** xv) : nice(xv);
    g.fillText(xl, m.l + ((w - m.l - m.r) * i) / 4 - 10, h - m.b + 14);
    g.fillText(nice(yv), 4, Y(yv) + 4);
  }
  if (options.xlabel) g.fillText(options.xlabel, w - m.r - g.measureText(options.xlabel).width, h - 4);
  if (options.ylabel) g.fillText(options.ylabel, m.l + 4, m.t + 10);
  let ly = m.t + 24;
  for (const s of series) {
    g.strokeStyle = s.colour || '#225';
    g.lineWidth = 1.5;
    g.beginPath();
    s.xs.forEach((x, i) => {
      const px = X(x), py = Y(s.ys[i]);
      if (i === 0) g.moveTo(px, py);
      else if (s.step) {
        g.lineTo(px, Y(s.ys[i - 1]));
        g.lineTo(px, py);
      } else g.lineTo(px, py);
    });
    g.stroke();
    if (s.label) {
      g.fillStyle = s.colour || '#225';
      g.fillText(s.label, m.l + 10, ly);
      ly += 14;
    }
  }
}

// The counting function N(λ) of the computed eigenvalues, and Weyl's law N(λ) ≈ slope·λ.
export function plotStaircase(canvas, eigenvalues, slope) {
  const xs = [0, ...eigenvalues], ys = [0, ...eigenvalues.map((_, i) => i + 1)];
  const series = [{ xs, ys, step: true, colour: '#1f4e79', label: 'N(λ), computed' }];
  if (slope > 0) {
    const top = eigenvalues[eigenvalues.length - 1] || 1;
    series.push({ xs: [0, top], ys: [0, slope * top], colour: '#c0392b', label: `Weyl: N(λ) ≈ ${nice(slope)}·λ` });
  }
  plotCurves(canvas, series, { xlabel: 'λ', ylabel: 'N(λ)' });
}

// A square matrix as a heat map with its labels.
export function plotMatrix(canvas, matrix, labels) {
  const { g, w, h } = setup(canvas);
  const n = matrix.length;
  if (!n) return;
  const size = Math.min(w - 70, h - 10) / n;
  const flat = matrix.flat().filter(isFinite);
  const lo = Math.min(...flat), hi = Math.max(...flat);
  for (let i = 0; i < n; i++) {
    for (let j = 0; j < n; j++) {
      g.fillStyle = rampCss((matrix[i][j] - lo) / (hi - lo || 1));
      g.fillRect(70 + j * size, 5 + i * size, size, size);
    }
    g.fillStyle = '#333';
    g.fillText(labels[i].slice(0, 8), 2, 5 + (i + 0.5) * size + 4);
  }
}
