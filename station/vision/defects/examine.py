"""Each candidate at full resolution: its patch and local wall model, a pore or a scratch
measured, and the tests that accept it as a defect or leave it as the cross-hatch's
residue (the ends' steps, a square end, the share along the hatch).

Part of ``station.vision.defects`` (its docstring tells the method).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import warnings

import cv2
import numpy as np
from scipy.special import ndtr

from station.vision.defects.config import Defect, DefectConfig, NOISE_FLOOR
from station.vision.defects.common import (
    is_along_hatch, circ_diff_deg, confidence_of, gauss_newton, mad_sigma, near_hatch, weighted_pca,
)
from station.vision.defects.wall import level_dip, line_band, local_patch, Patch
from station.vision.defects.rims import darkness_reader, grow_by_skirt
from station.vision.defects.scratches import BLUR_PRIOR_PX, measure_scratch
from station.vision.defects.pores import measure_pore


class KnownBlur(float):
    """The camera's blur (Gaussian sigma, px) known to within a variance (``var``, px^2):
    a float wherever a blur is taken as given, its variance read where a scratch's width
    trades off against it (``measure_scratch``)."""

    var: float

    def __new__(cls, value: float, var: float = 0.0) -> "KnownBlur":
        obj = super().__new__(cls, value)
        obj.var = float(var)
        return obj


def shared_blur(examined: list["ExaminedCandidate"]) -> tuple[float, float] | None:
    """The blur the examined scratches read themselves (``ExaminedCandidate.blur_read``),
    combined as one frame's (one lens, one focus): their inverse-variance mean with the
    prior (``BLUR_PRIOR_PX``) counted once, each read's share of it taken out. Returns
    (blur, its variance), or None when no scratch read one."""
    prior_b, prior_var = BLUR_PRIOR_PX[0], BLUR_PRIOR_PX[1] ** 2
    num, den, n = prior_b / prior_var, 1.0 / prior_var, 0
    for ex in examined:
        if ex.blur_read is None or not ex.blur_read[1] > 0:
            continue
        b, v = ex.blur_read
        own = 1.0 / v - 1.0 / prior_var  # the read's own precision, the prior's taken out
        if own <= 1e-9:
            continue
        num += b / v - prior_b / prior_var
        den += own
        n += 1
    if n == 0:
        return None
    return num / den, 1.0 / den


@dataclass
class ExaminedCandidate:
    """One candidate examined at full resolution: the defect it is, if any, and the
    region it covers (claimed, so that another candidate's seed in it is not measured
    twice)."""

    defect: Defect | None
    region: np.ndarray
    box: tuple[int, int, int, int] | None = None  # the region's box (None: the candidate's)
    #: a scratch's cover over the same box: its centre line, half its width plus the blur's
    #: reach either side (claimed too; None: the region alone)
    cover: np.ndarray | None = None
    #: a scratch's centre line (frame px, (n, 2), end to end) and its blur (px)
    line: np.ndarray | None = None
    blur: float | None = None
    #: which of a scratch's line's ends (its first point, its last) the measurement read
    #: where a groove's stretch begins (``_groove_beyond_end``, ``_shelf_beyond``): not
    #: followed on (``track_scratches``)
    groove_ends: tuple[bool, bool] = (False, False)
    #: a scratch's camera blur as it read it itself (px) and that reading's variance
    #: (px^2), when no blur was given (``measure_scratch``); None otherwise
    blur_read: tuple[float, float] | None = None


def examine_candidate(img: np.ndarray, box, seed: np.ndarray, zone: np.ndarray, angles_deg, wall_level: np.ndarray,
                      cfg: DefectConfig, blur_hint: float | None, max_width_px: float, excl: np.ndarray | None = None,
                      confine: tuple[float, float, float, float] | None = None,
                      others: np.ndarray | None = None, keep_out: np.ndarray | None = None,
                      hide: np.ndarray | None = None) -> ExaminedCandidate:
    """One candidate at full resolution: the local wall model, its region, its kind,
    its measurement and the tests it must pass.

    A scratch whose end the patch cuts (its strip runs out of the patch within reach
    of the end) is examined again in a patch grown along it: the patch is the box of
    the candidates that were found, and a long scratch near a groove direction breaks
    into pieces that are not joined (the twin's frames: a 161 px scratch 10 deg off the
    hatch measured as three overlapping scratches of 73, 99 and 129 px). So is a piece of
    a scratch along a groove direction that ends square at one end and runs on at the
    other (``_square_end``): the wall model's grooves along its line took the rest of it
    in, and the line is left out of them the second time. What a scratch covers, its
    centre line and blur, is claimed with its region, so that its other pieces are not
    measured again.

    ``excl``: what the first wall model leaves out besides the seed (a crossing furrow);
    ``confine``: a line the region keeps to (one furrow of several, ``split_furrows``);
    ``others``: what the defects measured so far cover over the frame, which the wall
    model leaves out in every patch; ``keep_out``: where the region may not grow (frame
    px: what another mark of the same seed covers, ``frame._seed_rest``); ``hide``: where the
    mark is not read at all (frame px: a pore a scratch runs through, whose darkness is
    no scratch's; the region keeps off it and a scratch's profiles pass it by)."""
    hh, ww = img.shape

    def beside(b) -> np.ndarray:
        return others[b[1]:b[3], b[0]:b[2]] if others is not None else False

    excl = (seed if excl is None else (seed | excl)) | beside(box)
    ex = None
    box0 = tuple(box)
    for attempt in range(3):
        again, m, kind = _examine_once(img, box, seed, excl, zone, angles_deg, wall_level, cfg, blur_hint,
                                       max_width_px, confine, line_out=attempt > 0, keep_out=keep_out,
                                       hide=hide)
        if ex is not None and ex.defect is not None and again.defect is None and not (
                box0[0] == 0 or box0[1] == 0 or box0[2] == ww or box0[3] == hh):
            # the grown patch lost it (bench frames: short scratches of 0.14-0.17 mm, taken for
            # a mark there): the cut one stands; but at the frame's border, where the first
            # patch had half a wall model round it, the grown patch's verdict (twin frames:
            # the hatch's residue at the border, 7 deg off a groove, stood as a 0.32 mm scratch).
            # Where neither patch made a defect, the grown one's piece is followed on: a bent
            # scratch along the hatch whose piece the grown patch cut again, one end square and
            # the other running on, was lost with the cut one's verdict (station frame 530015:
            # a 1.72 x 0.057 mm scratch 2 deg off the hatch, read as pieces of 106 and 111 px)
            break
        ex = again
        if kind != "scratch" or m is None or not (m.get("cut") or m.get("runs_on")) or attempt == 2:
            break
        # the ends (frame px), each moved out by as much again as the scratch is long
        (xa, ya), (xb, yb) = ((m["line"][0][i] + box[0], m["line"][1][i] + box[1]) for i in (0, -1))
        reach = max(60.0, m["length"])
        ux, uy = (xb - xa) / max(np.hypot(xb - xa, yb - ya), 1e-6), (yb - ya) / max(np.hypot(xb - xa, yb - ya), 1e-6)
        pa, pb = (xa - reach * ux, ya - reach * uy), (xb + reach * ux, yb + reach * uy)
        pad = 20
        new = (int(max(min(box[0], min(pa[0], pb[0]) - pad), 0)), int(max(min(box[1], min(pa[1], pb[1]) - pad), 0)),
               int(min(max(box[2], max(pa[0], pb[0]) + pad), ww)), int(min(max(box[3], max(pa[1], pb[1]) + pad), hh)))
        # no larger than the frame's quarter each way: a bound on the time, far beyond a scratch
        if (new == tuple(box) and not m.get("runs_on")) or (new[2] - new[0]) * (new[3] - new[1]) > ww * hh / 4:
            break
        shape = (new[3] - new[1], new[2] - new[0])
        grown_seed = np.zeros(shape, bool)
        grown_seed[box[1] - new[1]:box[3] - new[1], box[0] - new[0]:box[2] - new[0]] = seed | ex.region
        # the wall model leaves out the scratch's line over the reach it may continue
        line_mask = np.zeros(shape, np.uint8)
        cv2.line(line_mask, (int(round(pa[0] - new[0])), int(round(pa[1] - new[1]))),
                 (int(round(pb[0] - new[0])), int(round(pb[1] - new[1]))), 1, int(2 * m["half_band"] + 1))
        seed, excl, box = grown_seed, grown_seed | line_mask.astype(bool) | beside(new), new
    return ex


def _a_stray_disc(m: dict, box, cfg: DefectConfig) -> bool:
    """Whether a measured mark (``m``, in ``box``) is one of the frame's dark discs of a
    hole's size at none of the part's holes (``cfg.floor_test_exempt``): centred in one
    and at least ``cfg.stray_disc_min_share`` of its diameter long."""
    return any(np.hypot(m["x"] + box[0] - x, m["y"] + box[1] - y) <= d / 2.0
               and m["length"] >= cfg.stray_disc_min_share * d for x, y, d in cfg.floor_test_exempt)


def _examine_once(img: np.ndarray, box, seed: np.ndarray, excl: np.ndarray, zone: np.ndarray, angles_deg,
                  wall_level: np.ndarray, cfg: DefectConfig, blur_hint: float | None, max_width_px: float,
                  confine: tuple[float, float, float, float] | None = None, line_out: bool = False,
                  keep_out: np.ndarray | None = None, hide: np.ndarray | None = None, relevel: bool = False):
    """``examine_candidate`` in one patch: (the examined candidate, its measurement, its kind).
    ``excl``: what the local wall model leaves out (the seed, or more); ``confine``: the
    line the region keeps to (``examine_candidate``); ``line_out``: ``excl`` holds the mark's line
    (an examination again along it); ``relevel``: the level taken again with the candidate
    left out (``local_patch``), for a pore whose floor read under the bar."""
    patch = local_patch(img, box, excl, zone, angles_deg, wall_level,
                        2.0 * cfg.level_sigma_half_px if relevel else None)
    x0, y0, x1, y1 = box
    empty = np.zeros((y1 - y0, x1 - x0), bool)
    if patch is None:
        return ExaminedCandidate(None, empty, tuple(box)), None, None
    rs = cv2.GaussianBlur(patch.residual, (0, 0), 1.0)
    hidden = None
    if hide is not None:
        hidden = hide[y0:y1, x0:x1]
        if hidden.any():
            patch = replace(patch, residual=np.where(hidden, np.nan, patch.residual).astype(patch.residual.dtype))
        else:
            hidden = None
    use = ~patch.excluded
    noise_s = max(mad_sigma(rs[use]), NOISE_FLOOR)
    peak = float(rs[seed].max()) if seed.any() else 0.0
    # grown down to the noise, or to a share of the peak for a dark mark: a pore must not
    # run out along a groove's faint residue that touches it
    grow = (rs > max(cfg.grow_k * noise_s, cfg.grow_share * peak)) & ~zone[y0:y1, x0:x1]
    if confine is not None:
        grow &= line_band(grow.shape, (x0, y0), confine, cfg.furrow_half_band_px)
    if keep_out is not None:
        grow &= ~keep_out[y0:y1, x0:x1]
    if hidden is not None:
        grow &= ~hidden
    n_lab, labels = cv2.connectedComponents(grow.astype(np.uint8), connectivity=8)
    hit = np.unique(labels[seed & grow])
    hit = hit[hit > 0]
    if hit.size:
        region = np.isin(labels, hit)
    else:
        # a faint scratch found by the line response may leave no pixel above the growth
        # threshold at full resolution: the seed's darker half is its region
        region = seed & (rs > 0) & ~zone[y0:y1, x0:x1]
        if hidden is not None:
            region &= ~hidden
        if region.sum() < 8:
            return ExaminedCandidate(None, empty, tuple(box)), None, None
    def at_border_of(reg: np.ndarray) -> bool:
        touches = reg[0, :].any() or reg[-1, :].any() or reg[:, 0].any() or reg[:, -1].any()
        return bool(touches and (x0 == 0 or y0 == 0 or x1 == img.shape[1] or y1 == img.shape[0]))

    yy, xx = np.nonzero(region)
    wts = np.clip(rs[region], 1e-6, None)
    mx_, my_, ang, ext_l, ext_w = _extents(xx, yy, wts)
    ca, sa = np.cos(ang), np.sin(ang)
    elongated = ext_l >= cfg.scratch_elongation * ext_w and ext_l >= 12.0
    if hidden is not None and confine is not None:
        # a scratch read past a pore on a line its arms gave (``wall.line_through_blob``): it
        # is measured as one, and its measured length and width judge it (``_accept``); the
        # region's extents across a short arm in a wide band held the grooves' residue too
        # (a 22 px arm beside a 22 px pore read 45 x 24 px)
        elongated = True
    if elongated and is_along_hatch(float(np.rad2deg(ang) % 180.0), ext_l, angles_deg, cfg):
        # along the hatch: most such marks are the grooves' residue, and measuring each as a
        # scratch cost the twin's frames 1.26x their time; the ends' test on the region's
        # own axis first (loosely: a piece that runs on may be a longer scratch's)
        along = (xx - mx_) * ca + (yy - my_) * sa
        ends = np.array([along.min(), along.max()])
        blur0 = float(blur_hint) if blur_hint is not None else BLUR_PRIOR_PX[0]
        pre = dict(line=(mx_ + ends * ca, my_ + ends * sa), blur=blur0, width=max(ext_w - 2.0 * blur0, 1.0))
        if not any(_square_end(img, wall_level, x0, y0, pre, cfg, angles_deg, zone)):
            # a piece of groove the wall model left, or a pore with such a piece attached ...
            # unless the mark, measured as a line, crosses the hatch after all: the region's
            # axis is its pixels', and a groove's residue joined to a scratch 10 deg off the
            # hatch pulled it to 5.9 deg, its ends then read along the groove, and a 0.34 x
            # 0.042 mm scratch of contrast 0.61 was lost (640 x 480 frame, seed 982022). Only
            # strong marks are measured so: the residue the test drops is mostly faint, and
            # measured it stays along the hatch (station / wide clean frames 1996000 /
            # 1997000: 0 of 58 and 4 of 97, these of contrast 0.06-0.18)
            m_line = (measure_scratch(patch, region, blur_hint, angles_deg, cfg.groove_alignment_deg)
                      if peak >= cfg.along_hatch_remeasure_k * noise_s else None)
            if m_line is None or is_along_hatch(m_line["angle"], m_line["length"], angles_deg, cfg):
                if hidden is not None:
                    return ExaminedCandidate(None, region, tuple(box)), None, None
                return _core_pore(patch, rs, seed, region, zone[y0:y1, x0:x1], peak, box, at_border_of(region),
                                  angles_deg, cfg, max_width_px, blur_hint)

    def as_pore(reg: np.ndarray, allow_scratch: bool = True):
        # a pore is one cavity: of a region in parts, the part round the peak when it
        # passes as a pore alone (``_peak_part``); else the whole region, as it stood
        if hidden is not None:
            return reg, None  # only a scratch is read past what is hidden
        part, beside = _peak_part(reg, rs, seed)
        if beside is not None:
            mp = measure_pore(patch, part, cfg, blur_hint=blur_hint, beside=beside)
            if mp is not None and not mp.get("scratch") and \
                    _accept(mp, "pore", box, at_border_of(part), angles_deg, cfg, max_width_px, blur_hint) is not None:
                return part, mp
        return reg, measure_pore(patch, reg, cfg, allow_scratch=allow_scratch, blur_hint=blur_hint)

    if elongated:
        m = measure_scratch(patch, region, blur_hint, angles_deg, cfg.groove_alignment_deg)
    else:
        region, m = as_pore(region)
    if m is not None and m.get("scratch"):
        elongated = True
        m = measure_scratch(patch, region, blur_hint, angles_deg, cfg.groove_alignment_deg)
    kind = "scratch" if elongated else "pore"
    if kind == "scratch" and m is not None and m["length"] < cfg.scratch_elongation * m["width"]:
        region, m = as_pore(region, allow_scratch=False)  # short, broad
        kind = "pore"
    at_border = at_border_of(region)
    if kind == "scratch" and m is not None:
        m["along_share"] = _along_share(rs, region, m["angle"], angles_deg,
                                        beside=None if hidden is None else cv2.dilate(
                                            hidden.astype(np.uint8), cv2.getStructuringElement(
                                                cv2.MORPH_ELLIPSE, (2 * int(np.ceil(m["blur"])) + 1,) * 2)) > 0)
        m["along_hatch"] = is_along_hatch(m["angle"], m["length"], angles_deg, cfg)
        if near_hatch(m["angle"], angles_deg, cfg) is not None:
            # near the hatch: along it, a scratch if it ends in cuts (``_accept``); one cut end
            # and the other running on is a piece of a longer scratch (the wall model's
            # grooves along its line took the rest in), measured again along it (``examine_candidate``),
            # as is a piece of one that crosses the lines (``is_along_hatch``)
            m["square_end"], m["runs_on"] = _square_end(img, wall_level, x0, y0, m, cfg, angles_deg, zone)
            if line_out and not m["square_end"]:
                # measured again with its line left out of the grooves (``examine_candidate``): its ends
                # read on the residual too, where a groove it ran into is modelled from beside
                # its line rather than read as the mark running on (dev frames within 7.5 deg
                # of the hatch: 2 more of 114 scratches; none of the clean frames' pieces)
                # the holes' zone is not read there (NaN: an end it meets is not read, as one
                # the frame cuts is not): the residual is 0 in it, and a groove's stretch that
                # runs into a rim read as cut there (wide clean frame 1096029: a 0.63 mm
                # "scratch" between a crossing and a hole)
                res_img = np.where(patch.zone, np.nan, 1.0 - patch.residual).astype(np.float32)
                m["square_end"] = _square_end(res_img, np.ones_like(res_img), 0, 0, m, cfg, angles_deg)[0]
    defect = _accept(m, kind, box, at_border, angles_deg, cfg, max_width_px, blur_hint)
    if defect is not None and defect.kind == "pore" and not relevel and hidden is None \
            and not _a_stray_disc(m, box, cfg) \
            and level_dip(img, patch, region, 2.0 * cfg.level_sigma_half_px) > cfg.pore_relevel_dip:
        # a pore the frame's level dipped under: found, but not clearly dark where the
        # frame's level was taken (a large pale pore shares its darkness with the grooves'
        # means through it), so the level followed it, and its edges read short (the
        # twin's 0.5 mm pores at 0.6 of the wall's reflectance, over 10 % grooves: the
        # level 16 % down in the middle, lengths 3-18 % short). Measured again with the
        # level taken round it. Not a disc of a hole's size at none of the part's holes:
        # the frame's model reaches past those already, and the local level round one of
        # them (`bench surface --large-pores 3`, seed 96000) read it 10 % long (7 % under
        # the frame's level)
        again = _examine_once(img, box, seed, excl, zone, angles_deg, wall_level, cfg, blur_hint, max_width_px,
                              confine, line_out, keep_out, hide, relevel=True)
        if again[0].defect is not None and again[0].defect.kind == "pore":
            return again
    if defect is None and kind == "pore" and m is not None and m.get("faint") and not relevel:
        # a pore's floor under the bar: the frame's level leaves out what it found clearly
        # dark, and a large pale pore it did not find so pulled it down under itself (a
        # 0.45 x 0.32 mm pore, 0.37 dark, its long axis 15 deg off a groove family, shared
        # its lines' means with the deep grooves through it, stood under the dark floor,
        # lowered the level under it by a fifth and read a floor of 0.20: wide bench
        # 4540016, lost). Examined again with the level taken round it
        again = _examine_once(img, box, seed, excl, zone, angles_deg, wall_level, cfg, blur_hint, max_width_px,
                              confine, line_out, keep_out, hide, relevel=True)
        if again[0].defect is not None:
            return again
    if defect is None and hidden is None:
        core = _core_pore(patch, rs, seed, region, zone[y0:y1, x0:x1], peak, box, at_border, angles_deg, cfg,
                          max_width_px, blur_hint)
        if core[0].defect is not None:
            return core
        # else as it stood: a cut scratch that failed is examined again in a grown patch
    cover = None
    if defect is not None and kind == "scratch":
        # what the scratch covers: its centre line, its half width and blur either side
        lines = np.zeros(region.shape, np.uint8)
        pts = np.round(np.column_stack(m["line"])).astype(np.int32)
        cv2.polylines(lines, [pts], False, 1, int(2 * m["half_band"] + 1))
        cover = lines.astype(bool)
        line = np.column_stack(m["line"]) + np.array([x0, y0], float)
        return ExaminedCandidate(defect, region, tuple(box), cover, line, float(m["blur"]),
                                 m.get("groove_ends", (False, False)), m.get("blur_read")), m, kind
    return ExaminedCandidate(defect, region, tuple(box), cover), m, kind


def _round_peak(mask: np.ndarray, rs: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, int]:
    """The connected part (8-connected) of ``mask`` round the seed's darkest pixel in it
    (the seed must meet the mask), and how many parts the mask has."""
    n_lab, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    at = np.unravel_index(int(np.argmax(np.where(seed & mask, rs, -np.inf))), rs.shape)
    return labels == labels[at], n_lab - 1


def _extents(xx: np.ndarray, yy: np.ndarray, wts: np.ndarray) -> tuple[float, float, float, float, float]:
    """Pixels' weighted centre, principal direction (rad) and their extents along it and
    across it (px, end pixels included): (mx, my, angle, along, across)."""
    mx, my, ang, _ = weighted_pca(xx.astype(float), yy.astype(float), wts)
    ca, sa = np.cos(ang), np.sin(ang)
    return mx, my, ang, float(np.ptp(xx * ca + yy * sa)) + 1.0, float(np.ptp(-xx * sa + yy * ca)) + 1.0


def _peak_part(region: np.ndarray, rs: np.ndarray, seed: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Of a region in several parts, the part round the seed's darkest pixel, and the
    rest (None: one part): a pore is one cavity. A deep groove's stretch in line with a
    pore is a candidate grouped with it (``group_collinear``, which joins a faint
    scratch's pieces), and the pore was measured with the stretch beside it (a 30 px pore
    20 px from a stretch's end read 42 px, its place 8 px off; the surface bench's seed
    24203 lost a 0.31 mm pore so, read with the stretch as one broad faint mark)."""
    if not (seed & region).any():
        return region, None
    part, parts = _round_peak(region, rs, seed)
    if parts <= 1:
        return region, None
    return part, region & ~part


def _core_pore(patch: Patch, rs: np.ndarray, seed: np.ndarray, region: np.ndarray, zone: np.ndarray,
               peak: float, box, at_border: bool, angles_deg, cfg: DefectConfig, max_width_px: float,
               blur_hint: float | None):
    """A candidate whose region was no defect (``_examine_once``), looked at again for a
    pore in it: the region's part darker than ``cfg.core_share`` of its peak, round the
    peak. A deep groove's stretch that the frame's wall model does not hold (a groove
    that fades out along its line) joins a pore beside it in one region, and the pore
    was measured with it as one broad, faint mark or a piece of groove, and lost (the
    surface bench's seed 24203: a 0.31 mm pore of contrast ~0.6 at a groove's end, in a
    region three times its size). Only a compact core smaller than the region, measured
    as a pore and passing a pore's tests, stands, and only a dark one away from the
    frame's border (``cfg.core_min_peak``); else the candidate is nothing, as before.
    Returns what ``_examine_once`` does."""
    none = ExaminedCandidate(None, region, tuple(box)), None, None
    if peak < cfg.core_min_peak or at_border or not seed.any():
        return none
    dark = (rs > cfg.core_share * peak) & region & ~zone
    if not (seed & dark).any():
        return none
    core, _ = _round_peak(dark, rs, seed)
    n = int(core.sum())
    if n < 8 or n > cfg.core_max_share * int(region.sum()):
        return none  # no core, or the region is its core: measured as it stood
    yy, xx = np.nonzero(core)
    *_, ext_l, ext_w = _extents(xx, yy, np.clip(rs[core], 1e-6, None))
    if ext_l >= cfg.scratch_elongation * ext_w:
        return none  # a line: the furrows' and the scratches' business, not a pore's
    m = measure_pore(patch, core, cfg, allow_scratch=False, blur_hint=blur_hint)
    defect = _accept(m, "pore", box, at_border, angles_deg, cfg, max_width_px, blur_hint)
    if defect is None:
        return none
    return ExaminedCandidate(defect, core, tuple(box)), m, "pore"


def end_steps(img: np.ndarray, level: np.ndarray, x0: int, y0: int, m: dict,
              ends: tuple[int, ...] = (0, -1), other_deg: float | None = None,
              unread: np.ndarray | None = None) -> list[tuple[float, float]]:
    """How a mark measured as a line (``m``: its centre line, width and blur; patch offset
    ``x0``, ``y0``) steps down at each of its ``ends`` read (0: the first, -1: the last):
    (the step's width, px; its height as a share of the darkness inside). The raw
    relative darkness ``1 - img / level`` (the grooves kept) is read along the centre
    line's chord from up to 30 px inside the end to 30 px beyond it, the mean across the
    mark's core less that of its 4 px flanks (the other family's grooves cross both
    alike), and fitted as a blurred step (height, place, width, offset). An end the frame
    cuts is not read (no entry); a mark no darker inside than beyond reads (inf, 0).

    The step is fitted over its last ``_END_FIT_INSIDE_PX`` inside; the darkness inside
    it is measured against is the median over all of the inside read.

    ``other_deg``: the direction of the groove family that crosses a mark lying along the
    other (``_crossing_family``). Its grooves cross the core and the flanks at places
    along the line that differ by the flanks' offset over the tangent of the crossing
    angle (5-10 px at a 44 deg crossing), so core less flanks read a crossing groove as a
    peak beside a dip: at a deep groove's stretch that ended where a groove of the other
    family crossed it, a step 0.5-1.1 px wide of 0.9-1.1 of the darkness inside, sharper
    than the frame's blur allows an edge (wide clean frames 1097042, 1097051 at a 22 deg
    hatch: 1.14 and 0.84 mm "scratches"). That family's darkness is read along its own
    lines beside the mark (beyond the core, up to ``_CROSSING_READ_PX`` along them) and
    taken from every sample first, each sample by the line through it; ``unread`` (bool,
    the frame's shape, offset as ``img``): where those lines are not read (the holes'
    zone: a hole 20 px along them would read as the family's darkness)."""
    lx, ly = (np.asarray(v, float) for v in m["line"])
    if lx.size < 2:
        return []
    px, py = lx + x0, ly + y0
    length = float(np.hypot(px[-1] - px[0], py[-1] - py[0]))
    if length < 4.0:
        return []
    blur = float(np.clip(m["blur"], 0.7, 2.8))
    core = max(m["width"] / 2.0 + blur, 1.5)
    off = np.arange(-(core + 6.0), core + 6.0 + 0.25, 0.5)
    in_core, in_flank = np.abs(off) <= core, np.abs(off) >= core + 2.0
    inner = min(30.0, length / 2.0)
    t = np.arange(-inner, 30.0 + 0.25, 0.5)  # along the line, outwards from the end
    darkness = None  # the crossing family's lines' reader, made once when needed
    hh, ww = img.shape
    steps = []  # (width, share of the darkness) of each end read
    # along the chord: the centre line's last few px bend as its polynomial likes, and a
    # groove's piece read on past its end along them left the groove within 30 px (a
    # "square end": the twin's frames, 9 false scratches in 50 with this test's first form)
    cux, cuy = (px[-1] - px[0]) / length, (py[-1] - py[0]) / length
    for k, ux, uy in ((0, -cux, -cuy), (-1, cux, cuy)):
        if k not in ends:
            continue
        mx = px[k] + t[None, :] * ux - off[:, None] * uy
        my = py[k] + t[None, :] * uy + off[:, None] * ux
        bx0, by0 = int(max(np.floor(mx.min()) - 1, 0)), int(max(np.floor(my.min()) - 1, 0))
        bx1, by1 = int(min(np.ceil(mx.max()) + 2, ww)), int(min(np.ceil(my.max()) + 2, hh))
        if bx1 - bx0 < 2 or by1 - by0 < 2:
            continue
        dark = (1.0 - img[by0:by1, bx0:bx1].astype(np.float32)
                / np.maximum(level[by0:by1, bx0:bx1], 1.0)).astype(np.float32)
        st = cv2.remap(dark, (mx - bx0).astype(np.float32), (my - by0).astype(np.float32), cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
        s_b = np.zeros(0)
        if other_deg is not None:
            b = np.array([np.cos(np.deg2rad(other_deg)), np.sin(np.deg2rad(other_deg))])
            bn = float(b[0] * -uy + b[1] * ux)  # across the mark per px along the other family
            slope = float(b[0] * ux + b[1] * uy) / bn  # along the mark per px across it
            s_b = np.arange(-_CROSSING_READ_PX, _CROSSING_READ_PX + 0.5, 1.0)
            s_b = s_b[np.abs(s_b * bn) >= core + 2.0]  # beside the mark, off its core
        if s_b.size:
            t_b = np.arange(t[0] - (core + 7.0) * abs(slope), t[-1] + (core + 7.0) * abs(slope) + 0.5, 0.5)
            if darkness is None:
                darkness = darkness_reader(img, level, np.zeros(img.shape, bool) if unread is None else unread)
            sb = darkness(np.stack([px[k] + t_b[None, :] * ux + s_b[:, None] * b[0],
                                    py[k] + t_b[None, :] * uy + s_b[:, None] * b[1]], axis=-1))
            have = np.isfinite(sb).sum(axis=0)
            if (have >= 4).sum() >= 8:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore", RuntimeWarning)  # a line with nothing read
                    prof = np.where(have >= 4, np.nanmedian(sb, axis=0), np.nan)
                ok_b = np.isfinite(prof)
                # each sample less the other family's darkness on its line, where the line
                # meets the mark's centre line (the constant the lines pick up beside the
                # mark cancels in core less flanks)
                st = st - np.interp(t[None, :] - off[:, None] * slope, t_b[ok_b], prof[ok_b],
                                    left=np.nan, right=np.nan)
        ok = np.isfinite(st).all(axis=0)
        if ok.sum() < 20 or t[ok].max() < 12.0:
            continue  # the frame cuts this end
        a = st[in_core][:, ok].mean(axis=0) - st[in_flank][:, ok].mean(axis=0)
        tt = t[ok]
        inside, beyond = tt < -3.0 * blur, tt > 3.0 * blur
        if inside.sum() < 4:
            continue
        h_in = float(np.median(a[inside]))
        if h_in <= 0.0:
            steps.append((np.inf, 0.0))  # no darker inside than beyond: no end of a dark mark
            continue
        h_out = float(np.median(a[beyond])) if beyond.sum() >= 4 else 0.0
        # the step fitted over its last ``_END_FIT_INSIDE_PX`` inside (the darkness inside,
        # the share's reference, over all 30): a scratch's darkness varies along it (it
        # tapers, or bends off the chord), and over 30 px a plain step read a tapering
        # scratch's cut end as well as a step as wide as the taper, at the same cost to
        # 0.2 % (a station frame's 1.46 mm scratch 0.3 deg off the hatch, 542006: 0.7 or
        # 12 px as the data moved by a few thousandths)
        near = tt >= -_END_FIT_INSIDE_PX
        tn = tt[near]
        fit = gauss_newton(lambda q: q[0] * ndtr(-(tn - q[1]) / q[2]) + q[3],
                           np.array([max(h_in - h_out, 0.01), 0.0, 2.0, h_out]), a[near],
                           np.array([-1.0, -12.0, 0.4, -1.0]), np.array([2.0, 12.0, 30.0, 1.0]), iterations=25)
        steps.append((float(fit.x[2]), float(fit.x[0]) / h_in))
    return steps


#: how far along the crossing family's lines their darkness is read either side of a
#: mark's centre line (px; ``end_steps``)
_CROSSING_READ_PX = 24.0
#: how far inside a mark's end its step is fitted (px; ``end_steps``)
_END_FIT_INSIDE_PX = 15.0


def _crossing_family(line: tuple, angles_deg, cfg: DefectConfig) -> float | None:
    """The groove family that crosses a mark lying along the other (``line``: its centre
    line's x and y), at ``cfg.crossing_min_deg`` or more; None for a mark along neither
    family (both cross it) or where the families are too near to part."""
    lx, ly = (np.asarray(v, float) for v in line)
    if lx.size < 2 or len(angles_deg) < 2:
        return None
    mark = float(np.rad2deg(np.arctan2(ly[-1] - ly[0], lx[-1] - lx[0])) % 180.0)
    if near_hatch(mark, angles_deg, cfg) is None:
        return None
    far = max(angles_deg, key=lambda g: circ_diff_deg(mark, g))
    return float(far) if circ_diff_deg(mark, far) >= cfg.crossing_min_deg else None


def _square_end(img: np.ndarray, level: np.ndarray, x0: int, y0: int, m: dict,
                cfg: DefectConfig, angles_deg=(), unread: np.ndarray | None = None) -> tuple[bool, bool]:
    """Whether a scratch measured along a groove direction (``m``, patch offset ``x0``,
    ``y0``) ends in a cut at both ends, as a furrow does, rather than fading as a groove
    does, each end read on the raw darkness (the grooves kept: the wall model's grooves
    along such a line may have taken the mark in) by ``end_steps``. Returns (square,
    runs on): whether both ends are read, both step by at least
    ``cfg.square_end_min_height`` of the darkness inside, one of them square (no wider
    than ``cfg.square_end_max_width_px``, or 2.5 of the mark's blur) and the other no
    wider than ``cfg.square_end_other_max_width_px``, or both square in width with steps
    of at least ``cfg.square_end_sharp_min_height``; and whether one end is square while
    another runs on at more than ``cfg.square_end_max_run_on`` of the darkness (a piece
    of a longer mark). ``angles_deg``: the hatch's directions (the family crossing the
    mark is taken out of its ends' read, ``unread`` not read: ``end_steps``)."""
    steps = end_steps(img, level, x0, y0, m, other_deg=_crossing_family(m["line"], angles_deg, cfg),
                      unread=unread)
    max_width = max(cfg.square_end_max_width_px, 2.5 * float(np.clip(m["blur"], 0.7, 2.8)))
    square = [w <= max_width and h >= cfg.square_end_min_height for w, h in steps]
    ends = [w <= max(cfg.square_end_other_max_width_px, max_width) and h >= cfg.square_end_min_height
            for w, h in steps]
    runs_on = [h < 1.0 - cfg.square_end_max_run_on for _, h in steps]
    if len(steps) == 2 and all(w <= max_width for w, _ in steps) \
            and all(h >= cfg.square_end_sharp_min_height for _, h in steps):
        # cut at both ends: what lies on beyond one is another mark (a groove along the
        # line, or one of the other family crossing at the end)
        return True, any(runs_on)
    # both ends: one the frame cuts leaves a groove's piece at the border as square as a
    # scratch's (a fresh twin frame, 2080043); the scan's overlap sees such a scratch whole
    return len(steps) == 2 and any(square) and all(ends), any(square) and any(runs_on)


def _along_share(rs: np.ndarray, region: np.ndarray, angle_deg: float, angles_deg, sigma_px: float = 2.0,
                 grow_px: int = 3, beside: np.ndarray | None = None) -> float:
    """The share of the oriented gradient energy over ``region`` (grown by ``grow_px``, to
    take in the mark's flanks) whose local line direction is that of the scratch
    (``angle_deg``): nearer it than any groove direction (``angles_deg``) and within 10
    deg.  The local direction is the structure tensor's (the residual's gradient products
    over a Gaussian of ``sigma_px``), its weight the tensor's anisotropy (the flanks of a
    line carry it; flat noise little).  One straight furrow: ~0.9; deep grooves that
    cross, whose residue is a V or an X along the hatch: ~0.1-0.25. ``beside``: where
    another mark's edges lie (a pore the scratch runs through, with its skirt), not read."""
    gx = cv2.Sobel(rs, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(rs, cv2.CV_32F, 0, 1, ksize=3)
    jxx = cv2.GaussianBlur(gx * gx, (0, 0), sigma_px)
    jyy = cv2.GaussianBlur(gy * gy, (0, 0), sigma_px)
    jxy = cv2.GaussianBlur(gx * gy, (0, 0), sigma_px)
    area = cv2.dilate(region.astype(np.uint8), np.ones((2 * grow_px + 1,) * 2, np.uint8)).astype(bool)
    if beside is not None:
        area &= ~beside
    dxy, dd = 2.0 * jxy[area], (jxx - jyy)[area]
    weight = np.sqrt(dd * dd + dxy * dxy)
    total = float(weight.sum())
    if total <= 0.0:
        return 0.0
    line = (0.5 * np.degrees(np.arctan2(dxy, dd)) + 90.0) % 180.0  # the gradient's normal

    to_groove = (np.min([circ_diff_deg(line, float(g)) for g in angles_deg], axis=0) if len(angles_deg)
                 else np.full(line.shape, 180.0))
    along = circ_diff_deg(line, float(angle_deg)) < np.minimum(to_groove, 10.0)
    return float(weight[along].sum()) / total


def _accept(m: dict | None, kind: str, box, at_border: bool, angles_deg, cfg: DefectConfig,
            max_width_px: float, blur_hint: float | None) -> Defect | None:
    """The tests a measured mark must pass to be a defect, and the defect (``blur_hint``:
    the camera's blur if known, which the edge blur's bar follows)."""
    if m is None or m.get("faint"):
        return None
    # a mark cut by the frame's border has half the wall model round it (the grooves'
    # means and the level end there): twice the significance (dev and bench frames:
    # small "pores" in the frame's corners at 8.8-10.5)
    significance = m["significance"]
    if kind == "scratch" and not m.get("along_hatch", False):
        # a scratch's darkening weighed by its own cross profile (``line_significance``):
        # the box integrates a band of its profile's FWHM and 5 px each side, which a thin
        # line fills about a quarter of (station seed 994005: a 1.52 x 0.016 mm scratch, plain to see,
        # at 7.0 by the box, 17.4 along its line). Not along the hatch: a groove's piece is
        # such a line too, and the box alone judges it (a honing whose grooves stop short:
        # pieces at 10-35 by their line and under 8 by the box). A furrow's darkening is in
        # the box's band too, the line's figure at most ``cfg.line_significance_max_over_box``
        # times the box's: a mark read darker than its flanks along its line and not over
        # its band is light and dark side by side (the grooves' residue: a "scratch" at
        # 26.5 by its line, -6.2 by the box, groove-breaks bench 640259)
        line = float(m.get("line_significance", 0.0))
        significance = max(significance, min(line, cfg.line_significance_max_over_box * significance))
    if significance < cfg.min_significance * (2.0 if at_border else 1.0):
        return None
    if m["mean_darkness"] < cfg.min_mean_darkness:
        return None
    if kind == "pore" and m["length"] >= cfg.broad_pore_px and m["mean_darkness"] < cfg.min_broad_pore_darkness:
        return None  # broad and faint: the cross-hatch's residue, not a cavity
    if kind == "pore" and m["mean_darkness"] > cfg.max_pore_darkness_over_floor * m["contrast"] \
            and not _a_stray_disc(m, box, cfg):
        return None  # darker on the whole than its own fitted floor: no cavity's blurred step
    if kind == "scratch" and (m["contrast"] < cfg.min_scratch_contrast or m["blur"] > cfg.edge_blur_limit(blur_hint)
                              or m["width"] > max_width_px or m["length"] < cfg.scratch_elongation * m["width"]
                              or (m.get("along_hatch", False)
                                  and (not m.get("square_end", False)
                                       or m["contrast"] < cfg.aligned_min_scratch_contrast))
                              or m.get("along_share", 1.0) < cfg.min_scratch_along_share
                              or m["contrast"] * np.sqrt(max(m.get("along_share", 1.0), 0.0))
                              < cfg.min_scratch_line_contrast):
        return None  # the cross-hatch residue: broad, faint, soft, short, along a groove, not one line or faint, ragged
    conf = confidence_of(significance, cfg.min_significance)
    return Defect(kind, m["x"] + box[0], m["y"] + box[1], m["length"], m["width"], conf, m["angle"], m["u_length"],
                  m["u_width"], significance, at_border)
