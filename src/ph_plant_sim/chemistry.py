"""Acid-base chemistry by reaction invariants and the charge balance.

A *component* is a conserved chemical entity whose total concentration is a
reaction invariant: acid-base reactions only move protons between its
species, so the total is transported by flows and nothing else.

* a strong ion (Na+, NO3-, Cl-) has a fixed charge and no pKa;
* a weak acid system (carbonate, acetate, sulfate) has one pKa per
  dissociable proton and the charge ``charge`` of its fully protonated form
  (0 for H2CO3 and H2SO4, +1 for NH4+).

A *compound* is what a feed tank holds (HNO3, NaHCO3, NaOH): a recipe of
components per mole. Given the total concentration of every component, the
hydrogen-ion activity follows from electroneutrality

    f(pH) = [H+] - Kw/[H+] + sum_j C_j * zbar_j([H+]) = 0,

where zbar_j is the mean charge per mole of component j. f decreases strictly
with pH, so the root is unique; :meth:`ChargeBalance.ph` brackets it in
[0, 14]. Activities are taken equal to concentrations (dilute solutions).

Henson & Seborg's invariants map onto this directly: their Wa is
[NO3-] - [Na+] and Wb is the total carbonate.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy is imported where it is used (the scalar paths do not need it)
    import numpy as np

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

LN10 = math.log(10.0)
PH_MIN = 0.0
PH_MAX = 14.0


@dataclass(frozen=True)
class Component:
    """A conserved component.

    Attributes:
        name: identifier used in stream recipes and state vectors.
        charge: charge of the fully protonated species (strong ions: their charge).
        pka: successive acid dissociation constants, ascending; empty for a strong ion.
    """

    name: str
    charge: int
    pka: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if list(self.pka) != sorted(self.pka):
            raise ValueError(f"component {self.name!r}: pKa values must be ascending, got {list(self.pka)}")


#: Components the library knows. Custom ones are added through a chemistry spec.
COMPONENTS: dict[str, Component] = {
    c.name: c
    for c in (
        Component("sodium", +1),
        Component("potassium", +1),
        Component("calcium", +2),
        Component("nitrate", -1),
        Component("chloride", -1),
        # H2CO3* / HCO3- / CO3--, pK values of Henson & Seborg (1994).
        Component("carbonate", 0, (6.35, 10.25)),
        # H2SO4 / HSO4- / SO4--: first proton strong (pKa about -3), second pKa 1.99.
        Component("sulfate", 0, (-3.0, 1.99)),
        Component("acetate", 0, (4.76,)),
        Component("phosphate", 0, (2.15, 7.20, 12.35)),
        Component("ammonium", +1, (9.25,)),
    )
}

#: Compounds a feed may contain: moles of each component per mole of compound.
COMPOUNDS: dict[str, dict[str, float]] = {
    "HNO3": {"nitrate": 1.0},
    "HCl": {"chloride": 1.0},
    "H2SO4": {"sulfate": 1.0},
    "H2CO3": {"carbonate": 1.0},
    "CO2": {"carbonate": 1.0},
    "CH3COOH": {"acetate": 1.0},
    "H3PO4": {"phosphate": 1.0},
    "NaOH": {"sodium": 1.0},
    "KOH": {"potassium": 1.0},
    "NaHCO3": {"sodium": 1.0, "carbonate": 1.0},
    "Na2CO3": {"sodium": 2.0, "carbonate": 1.0},
    "CH3COONa": {"sodium": 1.0, "acetate": 1.0},
    "NH3": {"ammonium": 1.0},
    "NH4Cl": {"ammonium": 1.0, "chloride": 1.0},
    "NaCl": {"sodium": 1.0, "chloride": 1.0},
}


@dataclass
class Chemistry:
    """The set of components a plant tracks, and how compounds map onto them.

    ``components`` fixes the order of the state vector of concentrations.
    """

    components: list[Component]
    compounds: dict[str, dict[str, float]] = field(default_factory=lambda: dict(COMPOUNDS))
    pkw: float = 14.0

    @classmethod
    def for_streams(
        cls,
        streams: Sequence[Mapping[str, float]],
        extra_components: Sequence[Component] = (),
        extra_compounds: Mapping[str, Mapping[str, float]] | None = None,
        pkw: float = 14.0,
    ) -> "Chemistry":
        """Chemistry with exactly the components the given stream recipes use."""
        known = dict(COMPONENTS)
        known.update({c.name: c for c in extra_components})
        compounds = dict(COMPOUNDS)
        compounds.update({k: dict(v) for k, v in (extra_compounds or {}).items()})
        names: list[str] = []
        for stream in streams:
            for compound in stream:
                if compound not in compounds:
                    raise ValueError(f"unknown compound {compound!r}; known: {sorted(compounds)}")
                for comp in compounds[compound]:
                    if comp not in known:
                        raise ValueError(f"compound {compound!r} uses unknown component {comp!r}")
                    if comp not in names:
                        names.append(comp)
        return cls([known[n] for n in names], compounds, pkw)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.components]

    def concentrations(self, recipe: Mapping[str, float]) -> list[float]:
        """Component concentrations (mol/L) of a stream given as compound -> mol/L."""
        out = [0.0] * len(self.components)
        index = {c.name: i for i, c in enumerate(self.components)}
        for compound, conc in recipe.items():
            if conc < 0:
                raise ValueError(f"negative concentration {conc} of {compound!r}")
            for comp, nu in self.compounds[compound].items():
                out[index[comp]] += nu * conc
        return out

    def charge_balance(self) -> "ChargeBalance":
        return ChargeBalance(self.components, self.pkw)


class ChargeBalance:
    """Electroneutrality residual and its root, the pH.

    Built once per chemistry; :meth:`ph` is called every sample, so it is
    written for speed on a handful of components (a few microseconds).
    """

    def __init__(self, components: Sequence[Component], pkw: float = 14.0) -> None:
        self.kw = 10.0 ** (-pkw)
        self._strong = [(i, float(c.charge)) for i, c in enumerate(components) if not c.pka]
        # For an n-protic system, D(h) = sum_k K1..Kk h^(n-k) and
        # N(h) = sum_k k K1..Kk h^(n-k) (descending powers of h); the fraction
        # that lost k protons is K1..Kk h^(n-k) / D, the mean charge z0 - N/D.
        self._weak = []
        for i, c in enumerate(components):
            if c.pka:
                d_coef = [1.0]
                prod = 1.0
                for p in c.pka:
                    prod *= 10.0 ** (-p)
                    d_coef.append(prod)
                n_coef = [k * d for k, d in enumerate(d_coef)]
                self._weak.append((i, float(c.charge), tuple(d_coef), tuple(n_coef)))

    def _terms(self, conc: Sequence[float]) -> tuple[float, list]:
        strong = 0.0
        for i, z in self._strong:
            strong += z * conc[i]
        weak = [(conc[i], z0, d, n) for i, z0, d, n in self._weak if conc[i] != 0.0]
        return strong, weak

    def _residual(self, ph: float, strong: float, weak: list) -> tuple[float, float]:
        h = 10.0 ** (-ph)
        kw_h = self.kw / h
        f = h - kw_h + strong
        dfdh = 1.0 + kw_h / h
        for c, z0, d_coef, n_coef in weak:
            # Horner with derivative for D and N
            d = dd = 0.0
            for a in d_coef:
                dd = dd * h + d
                d = d * h + a
            n = dn = 0.0
            for a in n_coef:
                dn = dn * h + n
                n = n * h + a
            f += c * (z0 - n / d)
            dfdh -= c * (dn * d - n * dd) / (d * d)
        return f, dfdh * (-LN10 * h)

    def residual(self, ph: float, conc: Sequence[float]) -> tuple[float, float]:
        """Charge excess f (mol/L) at ``ph`` and its derivative df/dpH."""
        strong, weak = self._terms(conc)
        return self._residual(ph, strong, weak)

    def ph(self, conc: Sequence[float], guess: float = 7.0, tol: float = 1e-11, accept: float = 1e-6) -> float:
        """pH solving the charge balance, clamped to [0, 14].

        Safeguarded Newton (Newton steps inside a shrinking bracket, bisection
        when a step would leave it). Always converges: f is strictly
        monotone, and the bracket [0, 14] halves whenever Newton misbehaves.
        A root outside [0, 14] returns the nearer end. scipy's brentq gives
        the same root (tests check) but costs 10x more per call (its scalar
        Newton 50x), and this runs once per simulated sample.
        """
        strong, weak = self._terms(conc)
        lo, hi = PH_MIN, PH_MAX
        x = min(max(guess, lo), hi)
        for _ in range(200):
            f, df = self._residual(x, strong, weak)
            if f > 0.0:  # f decreases with pH: root is above x
                lo = x
            elif f < 0.0:
                hi = x
            else:
                return x
            if hi - lo < tol:
                break
            if df < 0.0:
                step = f / df
                # Newton's error after this step is about (f''/2f') step^2;
                # |f''/f'| stays below about 10 per pH unit, so a correction
                # below ``accept`` leaves an error below 10 * accept^2.
                if abs(step) < accept and lo < x - step < hi or abs(step) < tol:
                    x -= step
                    break
                x_new = x - step
                if not lo < x_new < hi:
                    x_new = 0.5 * (lo + hi)
            else:
                x_new = 0.5 * (lo + hi)
            x = x_new
        return min(max(x, PH_MIN), PH_MAX)

    def ph_array(self, conc: np.ndarray, guess: float | np.ndarray = 7.0, tol: float = 1e-11) -> np.ndarray:
        """pH for many compositions at once: conc has shape (N, n_components).

        The same safeguarded Newton as :meth:`ph`, run element-wise on arrays
        until every correction is below ``tol``. Each iteration works on the
        elements still iterating only (a trajectory far from its guess needs
        many more iterations near equivalence than elsewhere), so every
        element follows exactly the arithmetic it would alone.
        """
        import numpy as np

        conc = np.atleast_2d(np.asarray(conc, dtype=float))
        n = conc.shape[0]
        strong_all = np.zeros(n)
        for i, z in self._strong:
            strong_all += z * conc[:, i]
        out = np.clip(np.broadcast_to(np.asarray(guess, dtype=float), (n,)).copy(), PH_MIN, PH_MAX)
        idx = np.arange(n)  # the elements still iterating, and their state
        x = out.copy()
        lo = np.full(n, PH_MIN)
        hi = np.full(n, PH_MAX)
        strong = strong_all
        weak = [(conc[:, i], z0, d_coef, n_coef) for i, z0, d_coef, n_coef in self._weak]
        for _ in range(200):
            h = 10.0 ** (-x)
            kw_h = self.kw / h
            f = h - kw_h + strong
            dfdh = 1.0 + kw_h / h
            m = len(x)
            for c, z0, d_coef, n_coef in weak:
                d = np.zeros(m)
                dd = np.zeros(m)
                for a in d_coef:
                    dd = dd * h + d
                    d = d * h + a
                num = np.zeros(m)
                dnum = np.zeros(m)
                for a in n_coef:
                    dnum = dnum * h + num
                    num = num * h + a
                f += c * (z0 - num / d)
                dfdh -= c * (dnum * d - num * dd) / (d * d)
            df = dfdh * (-LN10 * h)
            lo = np.where(f > 0.0, x, lo)
            hi = np.where(f < 0.0, x, hi)
            step = np.where(df < 0.0, f / np.where(df < 0.0, df, -1.0), np.nan)
            x_newton = x - step
            ok = np.isfinite(x_newton) & (x_newton > lo) & (x_newton < hi)
            x_new = np.where(ok, x_newton, 0.5 * (lo + hi))
            done = (np.abs(step) < tol) | (hi - lo < tol) | (f == 0.0)
            x = np.where(done & np.isfinite(x_newton), x_newton, x_new)
            out[idx] = x
            if done.all():
                break
            if done.any():  # carry on with the elements still iterating
                keep = ~done
                idx, x, lo, hi, strong = idx[keep], x[keep], lo[keep], hi[keep], strong[keep]
                weak = [(c[keep], z0, d_coef, n_coef) for c, z0, d_coef, n_coef in weak]
        return np.clip(out, PH_MIN, PH_MAX)
