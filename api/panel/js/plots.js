// Line plots in plain SVG: axes with "nice" ticks, a light grid, a legend.
// Muted data colours (plots are information, not alarms).

const NS = "http://www.w3.org/2000/svg";
export const SERIES_COLOURS = ["#1f4e8c", "#5a5a5a", "#8c5a1f", "#3c7a6e", "#7a3c6e", "#2e2e2e"];

function el(name, attrs = {}, text) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  return e;
}

export function niceTicks(lo, hi, count = 6) {
  if (!isFinite(lo) || !isFinite(hi)) return [0];
  if (hi - lo < 1e-12) {
    const pad = Math.abs(lo) > 1e-9 ? Math.abs(lo) * 0.1 : 1;
    lo -= pad;
    hi += pad;
  }
  const raw = (hi - lo) / count;
  const mag = 10 ** Math.floor(Math.log10(raw));
  const step = [1, 2, 2.5, 5, 10].map((m) => m * mag).find((s) => s >= raw) || 10 * mag;
  const ticks = [];
  for (let v = Math.floor(lo / step) * step; v <= hi + step * 0.5; v += step) ticks.push(+v.toFixed(10));
  return ticks;
}

function fmt(v) {
  const a = Math.abs(v);
  if (a === 0) return "0";
  if (a >= 100) return v.toFixed(0);
  if (a >= 1) return v.toFixed(1).replace(/\.0$/, "");
  return v.toPrecision(2);
}

/**
 * plot(svg, {x, series: [{name, values, dashed}], xLabel, yLabel, points})
 * Draws into an SVG with a viewBox of 640 x 300.
 */
export function linePlot(svg, { x, series, xLabel = "", yLabel = "", markers = false, xTicks }) {
  while (svg.firstChild) svg.removeChild(svg.firstChild);
  const W = 640, H = 300, L = 62, R = 150, T = 14, B = 44;
  const all = series.flatMap((s) => s.values).filter((v) => v !== null && isFinite(v));
  if (!x.length || !all.length) {
    svg.appendChild(el("text", { x: W / 2, y: H / 2, "text-anchor": "middle" }, "no data"));
    return;
  }
  const xt = xTicks || niceTicks(Math.min(...x), Math.max(...x));
  const yt = niceTicks(Math.min(...all, 0), Math.max(...all, 0));
  const [x0, x1] = [xt[0], xt[xt.length - 1]];
  const [y0, y1] = [yt[0], yt[yt.length - 1]];
  const px = (v) => L + ((v - x0) / (x1 - x0 || 1)) * (W - L - R);
  const py = (v) => H - B - ((v - y0) / (y1 - y0 || 1)) * (H - T - B);

  for (const t of xt) {
    svg.appendChild(el("line", { x1: px(t), x2: px(t), y1: T, y2: H - B, class: "grid" }));
    svg.appendChild(el("text", { x: px(t), y: H - B + 16, "text-anchor": "middle" }, fmt(t)));
  }
  for (const t of yt) {
    svg.appendChild(el("line", { x1: L, x2: W - R, y1: py(t), y2: py(t), class: t === 0 ? "axis" : "grid" }));
    svg.appendChild(el("text", { x: L - 6, y: py(t) + 4, "text-anchor": "end" }, fmt(t)));
  }
  svg.appendChild(el("rect", { x: L, y: T, width: W - L - R, height: H - T - B, fill: "none", class: "axis" }));
  svg.appendChild(el("text", { x: (L + W - R) / 2, y: H - 8, "text-anchor": "middle" }, xLabel));
  const yl = el("text", { x: 14, y: (T + H - B) / 2, "text-anchor": "middle",
    transform: `rotate(-90 14 ${(T + H - B) / 2})` }, yLabel);
  svg.appendChild(yl);

  series.forEach((s, i) => {
    const colour = s.colour || SERIES_COLOURS[i % SERIES_COLOURS.length];
    const d = s.values.map((v, k) => `${k ? "L" : "M"}${px(x[k]).toFixed(1)},${py(v).toFixed(1)}`).join(" ");
    svg.appendChild(el("path", { d, fill: "none", stroke: colour, "stroke-width": 2,
      "stroke-dasharray": s.dashed ? "6 4" : "none" }));
    if (markers) {
      s.values.forEach((v, k) => svg.appendChild(el("circle", { cx: px(x[k]), cy: py(v), r: 3, fill: colour })));
    }
    const ly = T + 14 + i * 18;
    svg.appendChild(el("line", { x1: W - R + 12, x2: W - R + 36, y1: ly - 4, y2: ly - 4, stroke: colour,
      "stroke-width": 2, "stroke-dasharray": s.dashed ? "6 4" : "none" }));
    svg.appendChild(el("text", { x: W - R + 42, y: ly }, s.name));
  });
}
