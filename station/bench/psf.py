"""The benches' lens spread beyond the Gaussian blur (``station bench defects`` and
``station bench vision``): a defocus disc and a motion smear on the twin's frames
(``sim.camera.render.psf_kernel``), a world whose optics the station's model (a
Gaussian blur) does not hold."""

from __future__ import annotations

import typer


def psf_overrides(disc_px: float, smear_px: float, smear_deg: float) -> dict:
    """The renderer's ``FrameParams`` fields for a lens spread beyond the Gaussian: a
    defocus disc of radius ``disc_px`` and a smear of ``smear_px`` at ``smear_deg``
    (``sim.camera.render.psf_kernel``); empty for none, so the frames are the old ones."""
    out = {}
    if disc_px:
        out["psf_disc_px"] = float(disc_px)
    if smear_px:
        out |= {"psf_smear_px": float(smear_px), "psf_smear_deg": float(smear_deg)}
    return out


def psf_options():
    """The benches' three typer options for ``psf_overrides`` (defaults: none)."""
    return (typer.Option(0.0, "--psf-disc", min=0.0, max=6.0,
                         help="a defocused lens: a uniform disc of this radius (px) on top of the Gaussian blur"),
            typer.Option(0.0, "--psf-smear", min=0.0, max=12.0,
                         help="a camera or part moving during the exposure: a uniform smear of this length (px)"),
            typer.Option(0.0, "--psf-smear-deg", help="the smear's direction from the image's x axis (deg)"))


PSF_DISC, PSF_SMEAR, PSF_SMEAR_DEG = psf_options()


def psf_title(psf: dict) -> str:
    """A bench table title's words for its frames' extra spread ('' for none)."""
    words = []
    if psf.get("psf_disc_px"):
        words.append(f"a defocus disc of {psf['psf_disc_px']:g} px")
    if psf.get("psf_smear_px"):
        words.append(f"a {psf['psf_smear_px']:g} px smear at {psf['psf_smear_deg']:g} deg")
    return (", " + " and ".join(words)) if words else ""
