"""Each joint's type from its motion: about a single axis → revolute, otherwise spherical, with the evidence.

Segments with poses (O'Brien et al. 2000, section 3.2; :mod:`identcheck.estimate.obrien`): the three smallest
singular values of the stacked system give three *rotation spreads* φ₀ ≤ φ₁ ≤ φ₂ (degrees). For rotation about
one axis by an angle of RMS α they are (0, α, α); a ball joint turned about two or three axes has φ₀ as large as
its second-largest motion. φ₀ is the *wobble* off the best single axis, φ₁ the main rotation. The joint is
revolute when the wobble is below the larger of

- what noise alone leaves: :data:`NOISE_FACTOR` times the predicted φ₀ of a perfect hinge under the estimated
  marker noise (:func:`noise_wobble_deg`), and at least :data:`~identcheck.estimate.obrien.HINGE_TOL_DEG`;
- a wobbly hinge: :data:`HINGE_RATIO` of the main rotation, at most
  :data:`~identcheck.estimate.joint.MAX_OFF_AXIS_DEG` (skin markers add several degrees of off-axis rotation to a
  knee);

else spherical. A ball joint exercised about one axis only cannot be told from a hinge; the evidence says so.
``confidence`` is Φ(|ln(φ₀ / limit)| / ln :data:`CONFIDENCE_FACTOR`): 0.5 at the limit, 0.84 a factor 1.5 away.
A joint that hardly moves at all (φ₁ below the hinge tolerance) is written spherical, the general type, with
confidence 0.5.

One- or two-marker groups (:class:`identcheck.infer.tree.SmallFit`): revolute when the circle (hinge) fit
leaves at most :data:`CIRCLE_FACTOR` times the sphere (ball) fit's residual or the noise, whichever is larger,
or when no sphere fits plausibly; else spherical.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from identcheck.estimate.joint import MAX_OFF_AXIS_DEG
from identcheck.estimate.obrien import HINGE_TOL_DEG

NOISE_FACTOR = 3.0
HINGE_RATIO = 0.25
CONFIDENCE_FACTOR = 1.5
CIRCLE_FACTOR = 2.0


@dataclass(frozen=True)
class JointType:
    """A joint's type and why.

    Attributes
    ----------
    type : str
        "revolute" or "spherical".
    confidence : float
    evidence : dict
        JSON-plain numbers and the rule in words.
    """

    type: str
    confidence: float
    evidence: dict


def _phi(x: float) -> float:
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def noise_wobble_deg(local_parent: np.ndarray, local_child: np.ndarray, sigma_mm: float) -> float:
    """The wobble φ₀ (degrees) a perfect hinge would show under marker noise alone.

    A segment posed by Kabsch from markers at body coordinates L (centred) with noise σ per coordinate has a
    rotation error of variance about σ² / (⅔ Σ|L_k|²) about each axis; the relative rotation adds both segments',
    v, and its spread about the hinge axis, from the mean relative rotation, is arccos(1 − v) ≈ √(2v).

    Parameters
    ----------
    local_parent, local_child : array, shape (n_markers, 3)
        The segments' body-fixed marker coordinates, mm.
    sigma_mm : float
        Marker noise, one coordinate, mm.
    """
    def var(L):
        L = np.asarray(L, dtype=float)
        L = L - L.mean(axis=0)
        return sigma_mm ** 2 / max(2.0 / 3.0 * float(np.sum(L * L)), 1e-12)

    if not np.isfinite(sigma_mm):
        return float("nan")
    return float(np.degrees(np.sqrt(2.0 * (var(local_parent) + var(local_child)))))


def classify_posed(fit, noise_deg: float) -> JointType:
    """Type of a joint between two posed segments from its O'Brien fit (module docstring).

    Parameters
    ----------
    fit : identcheck.estimate.obrien.JointFit
    noise_deg : float
        :func:`noise_wobble_deg` for the two segments (NaN: unknown noise).
    """
    s0, s1, s2 = (float(x) for x in fit.spread_deg)
    clear = max(HINGE_TOL_DEG, NOISE_FACTOR * noise_deg if np.isfinite(noise_deg) else 0.0)
    wobbly = min(MAX_OFF_AXIS_DEG, HINGE_RATIO * s1)
    limit = max(clear, wobbly)
    ev = {"singular_values": [float(x) for x in fit.singular_values], "rotation_spread_deg": [s0, s1, s2],
          "wobble_deg": s0, "main_rotation_deg": s1, "noise_wobble_deg": None if not np.isfinite(noise_deg)
          else float(noise_deg), "hinge_limit_deg": float(limit), "n_frames": int(fit.n_frames)}
    if s1 < clear:
        ev["rule"] = (f"the segments hardly rotate relative to each other (rotation spreads {s0:.3g}, {s1:.3g}, "
                      f"{s2:.3g} deg): the type cannot be told; written spherical, the general type")
        return JointType("spherical", 0.5, ev)
    conf = _phi(abs(math.log(max(s0, 1e-12) / limit)) / math.log(CONFIDENCE_FACTOR))
    if s0 <= limit:
        ev["rule"] = (f"single axis: the relative rotation turns {s1:.3g} deg (RMS spread) about one axis and wobbles "
                      f"{s0:.3g} deg off it, within the hinge limit {limit:.3g} deg "
                      f"({_limit_words(clear, wobbly, noise_deg)}); a ball joint turned about one axis only would "
                      "look the same")
        return JointType("revolute", conf, ev)
    ev["rule"] = (f"more than one axis: the relative rotation spreads {s0:.3g} deg about its least-turned direction, "
                  f"beyond the hinge limit {limit:.3g} deg ({_limit_words(clear, wobbly, noise_deg)}); main "
                  f"rotation {s1:.3g} deg")
    return JointType("spherical", conf, ev)


def _limit_words(clear, wobbly, noise_deg) -> str:
    if clear >= wobbly:
        return (f"noise alone would leave {noise_deg:.2g} deg" if np.isfinite(noise_deg) else
                f"the hinge tolerance {HINGE_TOL_DEG:g} deg")
    return f"{HINGE_RATIO:g} of the main rotation, for skin-marker wobble"


def classify_small(small, sigma_mm: float) -> JointType:
    """Type of a joint to a one- or two-marker group from its sphere and circle fits (module docstring).

    Parameters
    ----------
    small : identcheck.infer.tree.SmallFit
    sigma_mm : float
        Marker noise, mm (NaN: unknown).
    """
    sph, cir = small.sphere_mm, small.circle_mm
    # the markers' noise as the parent's frame sees them: their own, grown by the parent's pose noise there (a thigh
    # posed by three markers along the femur turns its roll's noise into 6 mm off the knee's plane at the shank's
    # markers, 12 times their own 0.5 mm)
    own = sigma_mm if np.isfinite(sigma_mm) else 0.0
    seen = own * small.noise_factor
    ev = {"sphere_residual_mm": None if not np.isfinite(sph) else float(sph),
          "circle_residual_mm": None if not np.isfinite(cir) else float(cir),
          "travel_mm": float(small.travel_mm), "n_frames": int(small.n_frames),
          "noise_in_parent_mm": float(seen) if np.isfinite(sigma_mm) else None}
    if not np.isfinite(cir):
        ev["rule"] = "no circle (hinge) fits the markers' path in the parent's frame; a sphere (ball joint) does"
        return JointType("spherical", 0.84, ev)
    if not np.isfinite(sph):
        ev["rule"] = "a circle (hinge) fits the markers' path in the parent's frame, no plausible sphere does"
        return JointType("revolute", 0.84, ev)
    floor = max(sph, own, 1e-9)
    limit = CIRCLE_FACTOR * floor
    conf = _phi(abs(math.log(max(cir, 1e-12) / limit)) / math.log(CONFIDENCE_FACTOR))
    if cir <= limit:
        ev["rule"] = (f"the markers move on a circle in the parent's frame (circle residual {cir:.3g} mm, sphere "
                      f"{sph:.3g} mm): a hinge, or a ball joint turned about one axis only")
        return JointType("revolute", conf, ev)
    if cir <= CIRCLE_FACTOR * max(sph, seen, 1e-9):
        # within what the parent's pose noise leaves off a circle there, but not within the markers' own noise: a
        # hinge's path and a ball joint's are not told apart (a simulated hinged knee below a thigh posed along the
        # femur had been called a ball joint at full confidence; called a hinge there, 4 ball joints of a held-out
        # draw's were, against 7 hinges right): the general type, with a confidence that says so
        ev["rule"] = (f"the markers' path in the parent's frame fits a circle (residual {cir:.3g} mm, sphere "
                      f"{sph:.3g} mm) only within the noise the parent's pose adds there ({seen:.3g} mm, "
                      f"{small.noise_factor:.3g} times the markers' own): a hinge or a ball joint cannot be told "
                      "apart; written spherical, the general type")
        return JointType("spherical", 0.5, ev)
    wide = CIRCLE_FACTOR * max(sph, seen, 1e-9)      # (its confidence from there: 0.5 at the line, as beside it)
    ev["rule"] = (f"the markers move over a sphere, not a circle, in the parent's frame (sphere residual {sph:.3g} mm, "
                  f"circle {cir:.3g} mm > {CIRCLE_FACTOR:g} x {max(sph, seen, 1e-9):.3g} mm)")
    return JointType("spherical", _phi(abs(math.log(cir / wide)) / math.log(CONFIDENCE_FACTOR)), ev)
