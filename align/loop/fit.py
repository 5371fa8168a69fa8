"""What a stage of the residual loop fits and what it is offered: :class:`Term` (design
columns of one effect), :class:`StageFit` (one fit's residuals and estimates), the
:class:`Stage` protocol and :class:`Candidate` (an effect to try)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


@dataclass(frozen=True)
class Term:
    """Extra design columns for one effect.

    Attributes
    ----------
    name : str
        The effect's name (``earth_rate``, ``camera_roll[B]``).
    unit : str
        Unit of its estimate (``rad/s``, ``rad``).
    columns : ndarray, shape (N,) or (N, m)
        Regressors entering the stage's model linearly.
    searched : int
        Nonlinear parameters chosen by a search before fitting (e.g. a frequency), counted
        in BIC.
    trials : float
        Independent trials of that search (the look-elsewhere factor).
    meta : mapping of str to float
        What the stage needs to interpret the term (e.g. a period [s]).
    """

    name: str
    unit: str
    columns: np.ndarray
    searched: int = 0
    trials: float = 1.0
    meta: Mapping[str, float] = field(default_factory=dict)

    @property
    def width(self) -> int:
        return int(np.asarray(self.columns).reshape(len(self.columns), -1).shape[1])


@dataclass(frozen=True)
class StageFit:
    """What a stage returns from one fit.

    Attributes
    ----------
    residuals : ndarray, shape (N,)
        Observed minus fitted, in the observations' unit.
    sigma : ndarray, shape (N,), or None
        Their standard uncertainties (None: unknown, the tests then estimate the noise).
    n_params : int
        Parameters fitted (``dof`` = N - n_params; ``chi2`` = sum (r / sigma)^2).
    regressors : mapping of str to ndarray
        Quantities the residuals may depend on (time, period, position along a mark).
    order : str
        The regressor the structure tests order the residuals by.
    effects : mapping of str to (float, float)
        Per term name, (estimate, standard uncertainty) in the term's unit.
    quantities : mapping of str to (float, float)
        The stage's quantities of interest, name -> (value, u), SI/radians.
    components : mapping of str to tuple of (str, float, float)
        For effects with several parameters, (label, estimate, u) of each (the ``effects``
        entry is the most significant one).
    payload : object
        The stage's own fitted model.
    noise_dof : float or None
        Degrees of freedom of an *estimated* noise covariance behind ``sigma`` (None: sigma
        known); the effect and structure tests then use their null distributions with an
        estimated covariance (F- and t-type instead of chi2 and normal).
    """

    residuals: np.ndarray
    sigma: np.ndarray | None
    n_params: int
    regressors: Mapping[str, np.ndarray]
    order: str
    effects: Mapping[str, tuple[float, float]]
    quantities: Mapping[str, tuple[float, float]]
    components: Mapping[str, tuple[tuple[str, float, float], ...]] = field(default_factory=dict)
    payload: object = None
    noise_dof: float | None = None
    sequence: bool = True
    """False when the residuals are not independent in their order (a fit with fewer
    degrees of freedom than residuals whose projection correlates them, as the known-pose
    fit's 18 components in 6 dof): only the chi2 and regressor tests then apply."""

    @property
    def n(self) -> int:
        return int(len(self.residuals))

    @property
    def dof(self) -> int:
        return self.n - self.n_params

    @property
    def chi2(self) -> float:
        if self.sigma is None:
            return float(np.sum(self.residuals**2))
        return float(np.sum((self.residuals / self.sigma) ** 2))

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.residuals**2))) if self.n else float("nan")


class Stage(Protocol):
    def fit(self, terms: Sequence[Term]) -> StageFit: ...


@dataclass(frozen=True)
class Candidate:
    """A candidate effect.

    Attributes
    ----------
    name : str
        The effect's name (the Term's).
    unit : str
        Unit of its estimate.
    description : str
        What it is, for the report.
    build : callable
        ``build(current_fit) -> Term``: its columns from the current fit (None, or
        :class:`~axisbase.errors.NotApplicable` raised with the reason, if it does not
        apply).
    """

    name: str
    unit: str
    description: str
    build: Callable[[StageFit], Term | None]
