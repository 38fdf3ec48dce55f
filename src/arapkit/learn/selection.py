"""Choosing r per vertex from the energy table: ``r_k = argmin_r E_ARAP(k, r) + omega (r_max - r)``.

Choosing omega
--------------
``omega`` trades fit (E_ARAP grows with r where the shape bends) against rigidity. Where
E_ARAP(k, r) is convex in r, r_k is the largest r whose energy increment
``E_ARAP(k, r) - E_ARAP(k, r - 1)`` stays below omega, so omega is a threshold on increments.
The paper's 0.3 (:data:`PAPER_OMEGA`) suits its data sets; on skinned animations, whose
increments are much smaller, it gives r_max almost everywhere (899 of 901 vertices of the
panda walk). ``omega="auto"`` (:func:`auto_omega`) sets the threshold to the *mean* energy
increment per added ring over all vertices and steps (negative increments counted as 0):
a vertex whose energy grows faster than the shape's average gets a smaller r. The mean,
unlike a quantile, does not presume what fraction of the surface bends: parts that move
rigidly have increments near 0 and keep r_max, however large they are, while the joints
dominate the mean. On the panda walk it gives omega = 0.022 (r spread over 1..6, the head
rigid, shoulders and hips soft); on rigid motions, whose energies are rounding noise, the floor
:data:`AUTO_FLOOR` keeps r_max everywhere.

Examples
--------
>>> import numpy as np
>>> E = np.array([[0.0, 0.1, 0.5], [0.0, 0.0, 0.0]])
>>> select_rings(E, auto_omega(E), 1, 3).tolist()
[2, 3]
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError

__all__ = ["AUTO_FLOOR", "PAPER_OMEGA", "LearnedRings", "auto_omega", "choose_rings",
           "resolve_omega", "select_rings"]

#: The paper's omega (sec. 3.4: "omega = 0.3 in all our experiments").
PAPER_OMEGA = 0.3
#: Smallest automatic omega. E_ARAP is dimensionless (energy over area, roughly a squared
#: strain), so an absolute floor is meaningful: 1e-6 treats strains below ~0.1% as rigid.
#: It only matters when the examples are (nearly) rigid motions of the reference, whose
#: energies are rounding noise (1e-16 .. 1e-10 for float32 data) that must not decide r.
AUTO_FLOOR = 1e-6


def auto_omega(energies: np.ndarray) -> float:
    """Automatic omega: the mean energy increment per added ring, over all vertices.

    ``mean over k and r of max(E_ARAP(k, r + 1) - E_ARAP(k, r), 0)``: negative increments
    (a larger neighbourhood that fits better already favours the larger r) count as 0.
    The result is at least :data:`AUTO_FLOOR`. See the module notes for the reasoning.

    Examples
    --------
    >>> import numpy as np
    >>> auto_omega(np.array([[0.0, 0.1, 0.3], [0.0, 0.0, 0.0]]))
    0.075
    """
    E = np.asarray(energies, dtype=np.float64)
    if E.shape[1] < 2:
        return AUTO_FLOOR  # a single r: omega cannot change anything
    d = np.diff(E, axis=1)
    d = np.where(np.isfinite(d), np.maximum(d, 0.0), 0.0)
    return max(float(d.mean()), AUTO_FLOOR)


def select_rings(energies: np.ndarray, omega: float, r_min: int, r_max: int) -> np.ndarray:
    """``r_k = argmin_r E_ARAP(k, r) + omega (r_max - r)`` (ties go to the larger r).

    Examples
    --------
    >>> import numpy as np
    >>> select_rings(np.array([[0.0, 0.1, 0.5], [0.0, 0.0, 0.0]]), 0.2, 1, 3).tolist()
    [2, 3]
    """
    E = np.asarray(energies, dtype=np.float64)
    r = np.arange(r_min, r_max + 1)
    cost = E + omega * (r_max - r)[None, :]
    # argmin over the reversed columns: on a tie the most rigid choice wins
    return (r_max - np.argmin(cost[:, ::-1], axis=1)).astype(np.int32)


@dataclass
class LearnedRings:
    """Result of :func:`learn_rings`.

    Attributes
    ----------
    rings : (n,) int32
        Learned r per vertex, in ``[r_min, r_max]``.
    energies : (n, r_max - r_min + 1) float64
        ``E_ARAP(k, r)``; column j is r = r_min + j.
    areas : (n, r_max - r_min + 1) float64
        ``A(k, r)``, the normalising areas.
    omega : float
        The omega used.
    omega_rule : str
        ``"given"`` or ``"auto"`` (how omega was chosen).
    r_min, r_max : int
    n_examples : int
        Examples averaged (the reference excluded).
    identical : list of int
        Indices (into ``examples``) of examples equal to the reference; they carry no
        information and only dilute the mean.
    timings : dict
        ``neighbourhood_s`` (BFS), ``energy_s`` (kernel), ``total_s``.
    """

    rings: np.ndarray
    energies: np.ndarray
    areas: np.ndarray
    omega: float
    omega_rule: str
    r_min: int
    r_max: int
    n_examples: int
    identical: list[int] = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    def histogram(self) -> dict[int, int]:
        """Number of vertices per learned r.

        Examples
        --------
        >>> import numpy as np
        >>> LearnedRings(np.array([1, 3, 3]), np.zeros((3, 3)), np.ones((3, 3)), 0.3,
        ...              "given", 1, 3, 1).histogram()
        {1: 1, 2: 0, 3: 2}
        """
        counts = np.bincount(self.rings - self.r_min, minlength=self.r_max - self.r_min + 1)
        return {self.r_min + j: int(c) for j, c in enumerate(counts)}

    def with_omega(self, omega: float | str) -> LearnedRings:
        """The same energies, re-selected with another omega (no recomputation).

        Examples
        --------
        >>> import numpy as np
        >>> res = LearnedRings(np.array([2]), np.array([[0.0, 0.1]]), np.ones((1, 2)), 0.05,
        ...                    "given", 1, 2, 1)
        >>> res.with_omega(1.0).rings.tolist()
        [2]
        """
        value, rule = resolve_omega(omega, self.energies)
        return LearnedRings(select_rings(self.energies, value, self.r_min, self.r_max),
                            self.energies, self.areas, value, rule, self.r_min, self.r_max,
                            self.n_examples, list(self.identical), dict(self.timings))


def resolve_omega(omega: float | str, energies: np.ndarray) -> tuple[float, str]:
    """The omega to use and how it was chosen (``"given"`` or ``"auto"``).

    Examples
    --------
    >>> resolve_omega("0.3", np.zeros((1, 2))), resolve_omega("auto", np.zeros((1, 2)))
    ((0.3, 'given'), (1e-06, 'auto'))
    """
    if isinstance(omega, str):
        if omega.strip().lower() == "auto":
            return auto_omega(energies), "auto"
        try:
            omega = float(omega)
        except ValueError:
            raise InputError(f"omega must be a number >= 0 or 'auto', got {omega!r}") from None
    value = float(omega)
    if not np.isfinite(value) or value < 0:
        raise InputError(f"omega must be a number >= 0 or 'auto', got {omega!r}")
    return value, "given"


def choose_rings(energies: np.ndarray, areas: np.ndarray, omega: float | str, r_min: int,
                 r_max: int, n_examples: int, identical: list[int],
                 timings: dict) -> LearnedRings:
    """The :class:`LearnedRings` of an energy table: omega resolved, r selected.

    Examples
    --------
    >>> E = np.array([[0.0, 0.1, 0.5]])
    >>> choose_rings(E, np.ones_like(E), 0.2, 1, 3, 1, [], {}).rings.tolist()
    [2]
    """
    value, rule = resolve_omega(omega, energies)
    return LearnedRings(select_rings(energies, value, r_min, r_max), energies, areas, value,
                        rule, r_min, r_max, n_examples, identical, timings)
