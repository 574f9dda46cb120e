// An inspection's surface (issue 23): the unrolled picture of the bore wall in a viewer
// that zooms (mouse wheel about the pointer, +/- about the middle, reset to fit) and
// pans (drag), every defect marked at its place, rulers in axial mm (down the side)
// and angle on the table (along the top), and a table of the defects whose rows
// centre and zoom the viewer on theirs.
//
// The picture and its markers are one layer (the "stage", CSS-transformed by
// translate(tx, ty) scale(s) from its top left corner): a marker drawn at the picture
// pixel of its defect stays on it whatever the zoom. Only the markers' radius and the
// rulers are recomputed on a change of zoom (a marker keeps a few screen pixels at
// least). Place -> picture pixel (pixel edges at integers, a pixel's centre at +0.5),
// as the API documents it: x = ((angle - angle_from) mod 360) / deg_per_px,
// y = (axial - axial_from) / mm_per_px.

import { niceTicks } from "./plots.js";

const NS = "http://www.w3.org/2000/svg";
// muted data colours by kind (colour as information, not alarm); red is kept for a
// defect that breaks a criterion (its outline), in words too
export const KIND_COLOURS = { pore: "#1f4e8c", scratch: "#8c5a1f", burr: "#7a3c6e", chip: "#3c7a6e" };
const OTHER_COLOUR = "#2e2e2e";
const REJECT_COLOUR = "#c8102e";
// least radius of a marker on the screen (px), whatever the zoom
const MIN_MARKER_PX = 6;
const WHEEL_ZOOM_PER_PX = 0.0015; // zoom factor exp(-deltaY * this)
const BUTTON_ZOOM = 1.6;
const MAX_SCREEN_PX_PER_PICTURE_PX = 24;

function svg(name, attrs = {}, text) {
  const e = document.createElementNS(NS, name);
  for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, String(v));
  if (text !== undefined) e.textContent = text;
  return e;
}
function html(name, cls, text) {
  const e = document.createElement(name);
  if (cls) e.className = cls;
  if (text !== undefined) e.textContent = text;
  return e;
}
function has(v) {
  return v !== null && v !== undefined && isFinite(v);
}
function fmt(v, digits) {
  return has(v) ? Number(v).toFixed(digits) : "-";
}
function mod360(a) {
  return ((a % 360) + 360) % 360;
}

// steps of the angle ruler: each divides 360, so the labels stay round across 0 deg
const ANGLE_STEPS = [0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 15, 30, 45, 90, 180];

/** Ticks between a0 and a1 (deg, unwrapped) at a step that divides 360. */
function angleTicks(a0, a1, count) {
  const raw = (a1 - a0) / count;
  const step = ANGLE_STEPS.find((s) => s >= raw) || 180;
  const ticks = [];
  for (let k = Math.ceil(a0 / step - 1e-9); k * step <= a1 + 1e-9; k++) ticks.push(+(k * step).toFixed(6));
  return ticks;
}

/** Where a place on the part is on the picture (its pixels; edges at integers). */
export function pictureXY(pic, axialMm, angleDeg) {
  return { x: mod360(angleDeg - pic.angle_from_deg) / pic.deg_per_px, y: (axialMm - pic.axial_from_mm) / pic.mm_per_px };
}

/** "pore 0.231 ± 0.020 mm at 72.350 mm, 41.20 deg" (and what it breaks). */
export function defectText(d) {
  let t = `${d.kind} ${fmt(d.length_mm, 3)} \u00b1 ${fmt(d.size_u_mm, 3)} mm at ${fmt(d.axial_mm, 3)} mm, ` +
    `${fmt(d.angle_deg, 2)} deg`;
  if (d.hole) t += `, rim of ${d.hole}`;
  if (d.zone) t += `, zone ${d.zone}`;
  if (d.rejects) t += `; REJECTS: ${d.rejects}`;
  return t;
}

class SurfaceViewer {
  constructor(pic, defects) {
    this.pic = pic;
    this.defects = defects;
    this.W = pic.width_px;
    this.H = pic.height_px;
    this.s = 1;
    this.tx = 0;
    this.ty = 0;
    this.touched = false; // zoomed or panned by the operator: a resize does not refit
    this.markers = [];
    this.build();
  }

  build() {
    const root = html("div", "surface-viewer");
    const corner = html("div", "surface-corner");
    corner.append(html("span", "", "deg \u2192"), html("span", "", "mm \u2193"));
    corner.title = "axial position from the datum face (mm) down the side; angle on the table (deg) along the top";
    this.top = svg("svg", { class: "surface-ruler surface-ruler-top", "data-testid": "ruler-angle" });
    this.left = svg("svg", { class: "surface-ruler surface-ruler-left", "data-testid": "ruler-axial" });
    const vp = html("div", "surface-viewport");
    vp.tabIndex = 0;
    vp.setAttribute("aria-label", "unrolled picture of the bore wall: wheel or +/- to zoom, drag to pan");
    vp.dataset.testid = "surface-viewport";
    const stage = html("div", "surface-stage");
    const img = document.createElement("img");
    img.className = "surface-picture";
    img.alt = "unrolled picture of the bore wall";
    img.draggable = false;
    img.style.width = `${this.W}px`;
    img.style.height = `${this.H}px`;
    img.addEventListener("error", () => {
      vp.classList.add("missing");
      this.onMissing && this.onMissing();
    });
    img.src = this.pic.url;
    const marks = svg("svg", { class: "surface-marks", width: this.W, height: this.H, viewBox: `0 0 ${this.W} ${this.H}` });
    for (const d of this.defects) {
      if (!has(d.axial_mm) || !has(d.angle_deg)) continue;
      const { x, y } = pictureXY(this.pic, d.axial_mm, d.angle_deg);
      const colour = KIND_COLOURS[d.kind] || OTHER_COLOUR;
      const g = svg("g", { class: `surface-marker kind-${d.kind}` + (d.rejects ? " rejects" : ""),
        "data-defect-id": d.id, "data-kind": d.kind, "data-axial-mm": d.axial_mm, "data-angle-deg": d.angle_deg });
      const ring = svg("circle", { cx: x, cy: y, r: 1, class: "ring", stroke: colour, fill: colour });
      g.appendChild(ring);
      let outline = null;
      if (d.rejects) {
        outline = svg("circle", { cx: x, cy: y, r: 1, class: "reject-outline", stroke: REJECT_COLOUR, fill: "none" });
        g.appendChild(outline);
      }
      g.appendChild(svg("title", {}, defectText(d)));
      marks.appendChild(g);
      // the defect's own radius on the picture (half its length), the marker at least MIN_MARKER_PX on screen
      const own = has(d.length_mm) ? d.length_mm / 2 / this.pic.mm_per_px : 0;
      this.markers.push({ d, g, ring, outline, x, y, own });
    }
    stage.append(img, marks);
    vp.appendChild(stage);
    root.append(corner, this.top, this.left, vp);
    this.root = root;
    this.vp = vp;
    this.stage = stage;
    this.img = img;
    this.listen();
  }

  size() {
    return { w: this.vp.clientWidth, h: this.vp.clientHeight };
  }
  fitScale() {
    const { w, h } = this.size();
    return Math.min(w / this.W, h / this.H) || 1;
  }
  limits() {
    const fit = this.fitScale();
    return [fit * 0.5, Math.max(fit * 2, MAX_SCREEN_PX_PER_PICTURE_PX)];
  }

  /** The whole picture, centred. */
  fit() {
    const { w, h } = this.size();
    if (!w || !h) return;
    this.s = this.fitScale();
    this.tx = (w - this.W * this.s) / 2;
    this.ty = (h - this.H * this.s) / 2;
    this.touched = false;
    this.apply();
  }

  /** Zoom by ``factor`` keeping the viewport point (px, py) where it is on the picture. */
  zoomAt(factor, px, py) {
    const [lo, hi] = this.limits();
    const s = Math.min(hi, Math.max(lo, this.s * factor));
    this.tx = px - (px - this.tx) * (s / this.s);
    this.ty = py - (py - this.ty) * (s / this.s);
    this.s = s;
    this.touched = true;
    this.apply();
  }

  zoomCentre(factor) {
    const { w, h } = this.size();
    this.zoomAt(factor, w / 2, h / 2);
  }

  /** Centre the viewer on a defect, zoomed in on it. */
  focus(m) {
    const { w, h } = this.size();
    const [lo, hi] = this.limits();
    const target = Math.min(w, h) / Math.max(8 * m.own, 40);
    this.s = Math.min(hi, Math.max(lo, this.s, target));
    this.tx = w / 2 - m.x * this.s;
    this.ty = h / 2 - m.y * this.s;
    this.touched = true;
    for (const o of this.markers) o.g.classList.toggle("focused", o === m);
    this.apply();
  }

  apply() {
    this.stage.style.transform = `translate(${this.tx}px, ${this.ty}px) scale(${this.s})`;
    this.stage.classList.toggle("pixelated", this.s >= 3);
    // for whoever checks where a place is on the screen (the browser tests)
    this.vp.dataset.scale = String(this.s);
    this.vp.dataset.tx = String(this.tx);
    this.vp.dataset.ty = String(this.ty);
    // radius and strokes in screen pixels, whatever the zoom (the stage scales what it holds)
    const px = 1 / this.s;
    for (const m of this.markers) {
      const r = Math.max(m.own, MIN_MARKER_PX * px);
      m.ring.setAttribute("r", r);
      m.ring.setAttribute("stroke-width", (m.g.classList.contains("focused") ? 3.5 : 2) * px);
      if (m.outline) {
        m.outline.setAttribute("r", r + 3 * px);
        m.outline.setAttribute("stroke-width", 2.5 * px);
      }
    }
    this.drawRulers();
  }

  drawRulers() {
    const { w, h } = this.size();
    const pic = this.pic;
    const top = this.top, left = this.left;
    while (top.firstChild) top.removeChild(top.firstChild);
    while (left.firstChild) left.removeChild(left.firstChild);
    top.setAttribute("viewBox", `0 0 ${w} 26`);
    top.setAttribute("width", w);
    left.setAttribute("viewBox", `0 0 56 ${h}`);
    left.setAttribute("height", h);
    // angle along the top: the picture's columns in view, clipped to the picture
    const xa = (sx) => pic.angle_from_deg + ((sx - this.tx) / this.s) * pic.deg_per_px;
    const a0 = Math.max(xa(0), pic.angle_from_deg), a1 = Math.min(xa(w), pic.angle_to_deg);
    if (a1 > a0) {
      for (const t of angleTicks(a0, a1, Math.max(2, Math.round(w / 90)))) {
        if (t < a0 - 1e-9 || t > a1 + 1e-9) continue;
        const sx = this.tx + ((t - pic.angle_from_deg) / pic.deg_per_px) * this.s;
        if (sx < 14 || sx > w - 14) continue; // a label cut by the edge reads wrong
        top.appendChild(svg("line", { x1: sx, x2: sx, y1: 18, y2: 26, class: "tick" }));
        top.appendChild(svg("text", { x: sx, y: 14, "text-anchor": "middle" }, `${+mod360(t).toFixed(4)}`));
      }
    }
    // axial down the side
    const ya = (sy) => pic.axial_from_mm + ((sy - this.ty) / this.s) * pic.mm_per_px;
    const z0 = Math.max(ya(0), pic.axial_from_mm), z1 = Math.min(ya(h), pic.axial_to_mm);
    if (z1 > z0) {
      for (const t of niceTicks(z0, z1, Math.max(2, Math.round(h / 60)))) {
        if (t < z0 - 1e-9 || t > z1 + 1e-9) continue;
        const sy = this.ty + ((t - pic.axial_from_mm) / pic.mm_per_px) * this.s;
        if (sy < 6 || sy > h - 4) continue;
        left.appendChild(svg("line", { x1: 48, x2: 56, y1: sy, y2: sy, class: "tick" }));
        left.appendChild(svg("text", { x: 45, y: sy + 4, "text-anchor": "end" }, `${+t.toFixed(4)}`));
      }
    }
  }

  listen() {
    const vp = this.vp;
    vp.addEventListener("wheel", (ev) => {
      ev.preventDefault();
      const r = vp.getBoundingClientRect();
      const dy = ev.deltaMode === 1 ? ev.deltaY * 16 : ev.deltaMode === 2 ? ev.deltaY * r.height : ev.deltaY;
      this.zoomAt(Math.exp(-dy * WHEEL_ZOOM_PER_PX), ev.clientX - r.left, ev.clientY - r.top);
    }, { passive: false });
    let drag = null;
    vp.addEventListener("pointerdown", (ev) => {
      if (ev.button !== 0) return;
      drag = { x: ev.clientX, y: ev.clientY, tx: this.tx, ty: this.ty, id: ev.pointerId };
      vp.setPointerCapture(ev.pointerId);
      vp.classList.add("dragging");
    });
    vp.addEventListener("pointermove", (ev) => {
      if (!drag || ev.pointerId !== drag.id) return;
      this.tx = drag.tx + (ev.clientX - drag.x);
      this.ty = drag.ty + (ev.clientY - drag.y);
      this.touched = true;
      this.apply();
    });
    const end = (ev) => {
      if (!drag || ev.pointerId !== drag.id) return;
      drag = null;
      vp.classList.remove("dragging");
    };
    vp.addEventListener("pointerup", end);
    vp.addEventListener("pointercancel", end);
    vp.addEventListener("keydown", (ev) => {
      if (ev.key === "+" || ev.key === "=") this.zoomCentre(BUTTON_ZOOM);
      else if (ev.key === "-") this.zoomCentre(1 / BUTTON_ZOOM);
      else if (ev.key === "0") this.fit();
      else return;
      ev.preventDefault();
    });
    // the first layout (the section is built before it is on the page) and any resize
    const ro = new ResizeObserver(() => {
      if (!vp.isConnected) return ro.disconnect(); // the inspection shown is another now
      if (!this.touched) this.fit();
      else this.apply();
    });
    ro.observe(vp);
  }
}

function summaryText(surface) {
  const n = surface.defects.length;
  const rejecting = surface.defects.filter((d) => d.rejects).length;
  const parts = [`${n} defect${n === 1 ? "" : "s"}` + (rejecting ? `, ${rejecting} rejecting the part` : "")];
  parts.push(`${surface.frames} frames` + (surface.recentred ? ` + ${surface.recentred} re-centred` : ""));
  if (has(surface.coverage)) parts.push(`coverage ${fmt(surface.coverage * 100, 1)} %`);
  // the camera's blur the frames' defects were measured with, as the bore scan read it
  // at the holes' edges (absent: each frame read its own)
  if (has(surface.blur_px)) parts.push(`camera blur ${fmt(surface.blur_px, 2)} px (from the holes' edges)`);
  if (has(surface.axial_from_mm) && has(surface.axial_to_mm)) {
    parts.push(`axial ${fmt(surface.axial_from_mm, 2)} to ${fmt(surface.axial_to_mm, 2)} mm`);
  }
  return parts.join("; ");
}

/** One line for the current part: "surface: 3 defects, 1 rejecting the part; ..." */
export function surfaceLine(surface) {
  return `Surface: ${summaryText(surface)}`;
}

function legend() {
  const box = html("span", "surface-legend");
  for (const [kind, colour] of Object.entries(KIND_COLOURS)) {
    const item = html("span", "legend-item");
    const sw = html("span", "swatch");
    sw.style.borderColor = colour;
    sw.style.background = `${colour}33`;
    item.append(sw, document.createTextNode(kind));
    box.appendChild(item);
  }
  const item = html("span", "legend-item");
  const sw = html("span", "swatch reject");
  item.append(sw, document.createTextNode("red outline: rejects the part"));
  box.appendChild(item);
  return box;
}

/** The "Surface" section of an inspection (``rec.surface`` not null). */
export function surfaceSection(surface) {
  const box = html("section", "surface");
  box.dataset.testid = "surface";
  box.appendChild(html("h2", "list-title", "Surface"));
  box.appendChild(html("div", "part-info surface-summary", summaryText(surface)));
  const defects = surface.defects || [];
  let viewer = null;
  if (surface.picture) {
    viewer = new SurfaceViewer(surface.picture, defects);
    const bar = html("div", "surface-toolbar");
    const button = (text, title, cls, fn) => {
      const b = html("button", `cmd small ${cls}`, text);
      b.type = "button";
      b.title = title;
      b.addEventListener("click", fn);
      bar.appendChild(b);
    };
    button("+", "Zoom in (or the mouse wheel, about the pointer)", "zoom-in", () => viewer.zoomCentre(BUTTON_ZOOM));
    button("\u2212", "Zoom out", "zoom-out", () => viewer.zoomCentre(1 / BUTTON_ZOOM));
    button("Reset", "The whole picture", "zoom-reset", () => viewer.fit());
    bar.appendChild(legend());
    box.appendChild(bar);
    box.appendChild(viewer.root);
    const missing = html("div", "muted no-plot hidden", "The surface picture could not be loaded.");
    viewer.onMissing = () => missing.classList.remove("hidden");
    box.appendChild(missing);
  } else {
    box.appendChild(html("div", "muted no-plot", "No picture of the surface was kept with this inspection."));
  }
  if (surface.notes && surface.notes.length) {
    const ul = html("ul", "surface-notes");
    for (const n of surface.notes) ul.appendChild(html("li", "", n));
    box.appendChild(ul);
  }
  const t = html("table", "defects");
  t.dataset.testid = "defects";
  const thead = html("thead");
  const hr = html("tr");
  for (const [text, num] of [["Kind"], ["Axial mm", true], ["Angle deg", true], ["Size mm \u00b1 U", true],
    ["Hole / zone"], ["Verdict"]]) {
    hr.appendChild(html("th", num ? "num" : "", text));
  }
  thead.appendChild(hr);
  t.appendChild(thead);
  const tbody = html("tbody");
  for (const d of defects) {
    const tr = html("tr", d.rejects ? "fail" : "");
    tr.dataset.defectId = d.id;
    const kind = html("td", "kind");
    const sw = html("span", "swatch");
    const colour = KIND_COLOURS[d.kind] || OTHER_COLOUR;
    sw.style.borderColor = colour;
    sw.style.background = `${colour}33`;
    kind.append(sw, document.createTextNode(d.kind));
    tr.append(kind, html("td", "num", fmt(d.axial_mm, 3)), html("td", "num", fmt(d.angle_deg, 2)),
      html("td", "num", `${fmt(d.length_mm, 3)} \u00b1 ${fmt(d.size_u_mm, 3)}`),
      html("td", "", [d.hole, d.zone].filter(Boolean).join(" / ") || "-"),
      html("td", "verdict-cell", d.rejects ? `REJECT: ${d.rejects}` : "ok"));
    tr.title = defectText(d);
    const m = viewer && viewer.markers.find((o) => o.d === d);
    if (m) {
      tr.classList.add("focusable");
      tr.addEventListener("click", () => {
        tbody.querySelectorAll("tr.selected").forEach((r) => r.classList.remove("selected"));
        tr.classList.add("selected");
        viewer.focus(m);
      });
    }
    tbody.appendChild(tr);
  }
  if (!defects.length) {
    const tr = html("tr");
    const c = html("td", "muted", "No defects found.");
    c.colSpan = 6;
    tr.appendChild(c);
    tbody.appendChild(tr);
  }
  t.appendChild(tbody);
  box.appendChild(t);
  return box;
}
