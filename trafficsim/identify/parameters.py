"""Which ship-file coefficients an identification fits, their bounds and starting values.

A fit works on a subset of one family's ``coefficients`` (ship-file names and units, so what is
fitted is what a naval architect reads in the ship file); every other coefficient, the
particulars and the actuators come from a base ship. :class:`Parametrisation` turns parameter
vectors into ship specs and packed kernel rows, ``k`` candidates at a time.

Default subsets (documented choices):

* ``nomoto``: all five coefficients (K', T', n3', rps_service, surge_tau_s).
* ``response``: all sixteen coefficients of [seed 001, eq 2] (``a1..a9, b1..b4, c1..c3``).
* ``mmg`` (and ``mmg_berthing``, with its resistance ahead ``X_0F`` for ``R0``): the
  resistance ``R0``, the linear hull derivatives ``Y_v, Y_r, N_v, N_r``, the
  surge-sway coupling ``X_vr`` (speed loss in a turn) and the rudder's normal-force slope
  ``f_alpha``; propeller, interaction, added-mass and non-linear hull coefficients stay at the
  base ship's values. Fitting every MMG coefficient from a few runs is ill-posed (strongly
  correlated, many unidentifiable without captive tests); this subset is the part a few
  manoeuvres determine, and the report's correlation matrix shows how well.

Bounds keep candidates physical (damping negative, areas and fractions in range); they are
the ones below unless the user gives others (``trafficsim identify`` checks those against the
range the ship file takes for the coefficient, :func:`check_physical`).
"""

from __future__ import annotations

import copy
import difflib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from trafficsim.errors import InputError
from trafficsim.identify.replay import ModelRows, model_rows
from trafficsim.ships.base import families

INF = float("inf")

DEFAULT_FIT: dict[str, tuple[str, ...]] = {
    "nomoto": ("K_prime", "T_prime", "n3_prime", "rps_service", "surge_tau_s"),
    "response": ("a1", "a2", "a3", "a4", "a5", "a6", "a7", "a8", "a9", "b1", "b2", "b3", "b4",
                 "c1", "c2", "c3"),
    "mmg": ("R0", "X_vr", "Y_v", "Y_r", "N_v", "N_r", "f_alpha"),
    "mmg_berthing": ("X_0F", "X_vr", "Y_v", "Y_r", "N_v", "N_r", "f_alpha"),
}

#: (lower, upper) per coefficient; absent = unbounded
BOUNDS: dict[str, dict[str, tuple[float, float]]] = {
    "nomoto": {"K_prime": (0.01, 50.0), "T_prime": (0.02, 200.0), "n3_prime": (0.0, 5000.0),
               "rps_service": (1e-3, 1e3), "surge_tau_s": (0.1, 1e5)},
    # resistance, sway damping and yaw damping keep their stabilising signs
    "response": {"a1": (-INF, 0.0), "b1": (-INF, 0.0), "c2": (-INF, 0.0)},
    "mmg": {
        "R0": (0.0, 0.5), "X_vv": (-2.0, 2.0), "X_vr": (-2.0, 2.0), "X_rr": (-1.0, 1.0),
        "X_vvvv": (-10.0, 10.0), "Y_v": (-3.0, 0.0), "Y_r": (-1.0, 1.0),
        "Y_vvv": (-20.0, 20.0), "Y_vvr": (-10.0, 10.0), "Y_vrr": (-10.0, 10.0),
        "Y_rrr": (-5.0, 5.0), "N_v": (-1.0, 1.0), "N_r": (-1.0, 0.0), "N_vvv": (-5.0, 5.0),
        "N_vvr": (-5.0, 5.0), "N_vrr": (-5.0, 5.0), "N_rrr": (-2.0, 2.0),
        "m_x": (0.0, 0.3), "m_y": (0.0, 1.0), "J_z": (0.0, 0.2), "k_zz": (0.1, 0.5),
        "t_P": (0.0, 0.6), "w_P0": (0.0, 0.9), "x_P": (-1.0, 0.0),
        "t_R": (0.0, 0.9), "a_H": (0.0, 1.5), "x_H": (-1.0, 0.0), "x_R": (-0.6, -0.3),
        "gamma_R_plus": (0.05, 2.0), "gamma_R_minus": (0.05, 2.0), "l_R": (-2.0, 0.0),
        "epsilon": (0.3, 3.0), "kappa": (0.0, 1.5), "f_alpha": (0.3, 10.0),
        "C_1": (0.0, 10.0), "C_2_plus": (0.1, 5.0), "C_2_minus": (0.1, 5.0),
        "astern_thrust_ratio": (0.1, 1.5),
    },
    # the low-speed model's resistance coefficients are negative (X_0F, X_0A), its cross-flow
    # drag positive; the rest as for mmg
    "mmg_berthing": {
        "X_0F": (-0.5, 0.0), "X_0A": (-0.5, 0.0), "X_vr": (-2.0, 2.0), "Y_v": (-3.0, 0.0),
        "Y_r": (-1.0, 1.0), "N_v": (-1.0, 1.0), "N_r": (-1.0, 0.0), "C_D": (0.0, 5.0),
        "C_rY": (0.0, 5.0), "C_rN": (0.0, 5.0),
        "m_x": (0.0, 0.3), "m_y": (0.0, 1.0), "J_z": (0.0, 0.2), "k_zz": (0.1, 0.5),
        "t_P": (0.0, 0.6), "w_P0": (0.0, 0.9), "x_P": (-1.0, 0.0),
        "t_R": (0.0, 0.9), "a_H": (0.0, 1.5), "x_H": (-1.0, 0.0), "x_R": (-0.6, -0.3),
        "gamma_R_plus": (0.05, 2.0), "gamma_R_minus": (0.05, 2.0), "l_R": (-2.0, 0.0),
        "epsilon": (0.3, 3.0), "k_x": (0.0, 1.5), "f_alpha": (0.3, 10.0),
    },
}


def default_bounds(model: str, name: str) -> tuple[float, float]:
    return BOUNDS.get(model, {}).get(name, (-INF, INF))


def check_physical(model: str, bounds: Mapping[str, tuple[float, float]] | None) -> None:
    """Refuse user bounds reaching outside the range a ship file of family ``model`` takes for
    the coefficient (its ``limits``): a fit inside them could end where no ship file holds it.
    An InputError names ``--bounds``, the coefficient and what is allowed."""
    limits = families()[model].limits
    for name, (low, high) in (bounds or {}).items():
        limit = limits.get(name)
        problem = (limit.problem(low) or limit.problem(high)) if limit else None
        if problem:
            raise InputError(f"{name}={low:g}:{high:g} reaches outside the physical range of "
                             f"{name}, which {problem}; give bounds inside it", key="--bounds")


@dataclass
class Parametrisation:
    """Fitted coefficient names of a base ship spec, with bounds.

    Attributes:
        spec: the base ship spec (parsed ship file, family ``spec['model']``); its coefficients
            give every value not fitted and the default starting point.
        names: ``(p,)`` fitted coefficient names (ship-file units).
        lower, upper: ``(p,)`` bounds.
    """

    spec: dict[str, Any]
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def of(cls, spec: Mapping[str, Any], names: Sequence[str] | None = None,
           bounds: Mapping[str, tuple[float, float]] | None = None) -> Parametrisation:
        """Check ``names`` against the family's coefficients; default subset and bounds."""
        model = spec["model"]
        declared = families()[model].coefficients
        chosen = tuple(names) if names else DEFAULT_FIT.get(model, tuple(declared))
        for name in chosen:
            if name not in declared:
                close = difflib.get_close_matches(name, list(declared), n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else ""
                raise InputError(f"unknown coefficient '{name}' for model '{model}'{hint}; "
                                 f"expected some of {', '.join(declared)}", key="--fit")
        if len(set(chosen)) != len(chosen):
            raise InputError(f"coefficient listed twice in {', '.join(chosen)}", key="--fit")
        user = dict(bounds or {})
        for name in user:
            if name not in chosen:
                raise InputError(f"bounds given for '{name}', which is not fitted "
                                 f"(fitted: {', '.join(chosen)})", key="--bounds")
        lo = np.array([user.get(n, default_bounds(model, n))[0] for n in chosen], dtype=float)
        hi = np.array([user.get(n, default_bounds(model, n))[1] for n in chosen], dtype=float)
        bad = [n for n, a, b in zip(chosen, lo, hi, strict=True) if not a < b]
        if bad:
            raise InputError(f"empty bounds for {', '.join(bad)} (lower must be below upper)",
                             key="--bounds")
        return cls(copy.deepcopy(dict(spec)), chosen, lo, hi)

    @property
    def model(self) -> str:
        return str(self.spec["model"])

    @property
    def p(self) -> int:
        return len(self.names)

    def initial(self) -> np.ndarray:
        """The base ship's values of the fitted coefficients, clipped into the bounds."""
        x = np.array([float(self.spec["coefficients"][n]) for n in self.names])
        return np.clip(x, self.lower, self.upper)

    def specs(self, thetas: np.ndarray) -> list[dict[str, Any]]:
        """Ship specs with the fitted coefficients set to each row of ``thetas`` ``(k, p)``."""
        out = []
        for theta in np.atleast_2d(thetas):
            spec = dict(self.spec)
            coeffs = dict(spec["coefficients"])
            coeffs.update({n: float(v) for n, v in zip(self.names, theta, strict=True)})
            spec["coefficients"] = coeffs
            out.append(spec)
        return out

    def rows(self, thetas: np.ndarray) -> ModelRows:
        """Packed kernel rows of the candidates ``thetas`` ``(k, p)``."""
        return model_rows(self.specs(thetas))
