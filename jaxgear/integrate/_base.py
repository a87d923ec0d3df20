"""The integration strategy interface: what every analysis asks of an integrator.

An integrator advances the forced system ``x' = f(t, x, params)`` (paper eq. 6) over
whole forcing periods. Analyses never check which integrator they were given: they
call these operations.

- :meth:`AbstractIntegrator.advance` — a batch of states ``(dim, n)`` (struct of
  arrays: each coordinate one contiguous vector) over ``periods`` forcing periods;
- :meth:`AbstractIntegrator.trajectory` — the same, sampled for figures;
- :meth:`AbstractIntegrator.flow` — one state ``(dim,)``, differentiable with
  ``jax.jacfwd`` (monodromy matrices) and ``jax.grad`` (design);
- :meth:`AbstractIntegrator.segment_flow` — one of the equal segments of a P-k orbit
  (multiple shooting), with :meth:`AbstractIntegrator.check_segments` saying which
  numbers of segments the integrator can cut ``k`` periods into;
- :attr:`AbstractIntegrator.crossing_stepper` — the fixed-step integrator that brackets
  and locates crossings of a Poincaré section.

Times are in the system's own unit (dimensionless ``tau = omega_n t`` for the gear
models); ``periods`` is a Python int (it sets the length of a compiled loop).
"""

from __future__ import annotations

import abc
import dataclasses
import functools
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._checks import check_int

__all__ = ["AbstractIntegrator", "AbstractFixedStep", "DEFAULT_STEPS_PER_PERIOD", "batch_field",
           "check_steps_per_period", "stack_params"]

DEFAULT_STEPS_PER_PERIOD = 200
"""Fixed steps per forcing period of the default integrator (the one place it is set)."""


def check_steps_per_period(value, name: str = "steps_per_period") -> int:
    """``value`` as an int >= 1, else ``ValueError`` naming ``name``, the value and the range."""
    return check_int(value, name, 1)


@functools.partial(jax.jit, static_argnums=0)
def batch_field(system, params, t, Y):
    """The vector field on a batch ``Y (dim, n)``: ``dY/dt (dim, n)``.

    ``t`` is a scalar (time-only terms, such as the mesh stiffness and errors of the gear
    models, are then computed once for the whole batch) or an ``(n,)`` array (one time
    per lane).

    A ``jit`` of its own, though always called inside a kernel: a step evaluates the field
    many times at the same shapes (four stages, the kink-aware step's sub-steps), and
    JAX traces a jitted function once per shapes and reuses it, where a plain function is
    traced at every call (the compiled kernel inlines it: the same program).
    """
    in_t = None if jnp.ndim(t) == 0 else 0
    return jax.vmap(system.vector_field, in_axes=(in_t, 1, None), out_axes=1)(t, Y, params)


def stack_params(params_list):
    """Several parameter pytrees of one structure as one, every numeric leaf with a
    leading axis of ``len(params_list)`` rows (static fields must agree)."""
    return jax.tree.map(lambda *a: jnp.stack([jnp.asarray(x) for x in a]), *params_list)


class AbstractIntegrator(eqx.Module):
    """An integration strategy for a :class:`~jaxgear.ForcedSystem` (see the module).

    Concrete integrators are immutable configuration objects (hashable: they are static
    arguments of compiled kernels) and serialise to a dict with :meth:`to_dict`.
    """

    name: ClassVar[str] = "abstract"

    @abc.abstractmethod
    def advance(self, system, params, Y, t0, periods: int, n_active=None):
        """Advance ``Y (dim, n)`` from ``t0`` by ``periods`` forcing periods: ``(dim, n)``.

        A lane that blew up is non-finite (never a silently wrong value). ``n_active``
        (a traced int, optional): only lanes ``[0, n_active)`` matter, the others may be
        returned unchanged (the compiled CPU kernel skips them; others compute all).
        """

    def advance_rows(self, system, params_rows, rows, Y, t0, periods: int, n_active=None):
        """:meth:`advance` with one parameter set per lane: ``params_rows`` is the
        parameter pytree with a leading axis of ``V`` rows on every numeric leaf
        (:func:`stack_params`), ``rows (n,)`` int the row of each lane of ``Y (dim, n)``.

        Each lane is advanced exactly as :meth:`advance` would with its own parameters
        (here by mapping it over the lanes; the compiled CPU kernel reads the rows
        itself). ``n_active`` as in :meth:`advance`.
        """
        def one(y, r):
            p = jax.tree.map(lambda a: a[r], params_rows)
            return self.advance(system, p, y[:, None], t0, periods)[:, 0]

        return jax.vmap(one, in_axes=(1, 0), out_axes=1)(Y, rows)

    @abc.abstractmethod
    def trajectory(self, system, params, Y, t0, periods: int, samples_per_period: int):
        """Samples for figures: times ``(m + 1,)`` and states ``(m + 1, dim, n)`` with
        ``m = periods * samples_per_period``, from ``t0`` to ``t0 + periods * T``."""

    def flow(self, system, params, x, t0, periods: int):
        """``P^periods`` of one state ``x (dim,)``: ``(dim,)``, differentiable both ways."""
        return self.advance(system, params, x[:, None], t0, periods)[:, 0]

    def check_segments(self, periods: int, segments: int) -> None:
        """Raise ``ValueError`` unless ``periods`` forcing periods split into ``segments``
        equal pieces this integrator can run: here whole periods, ``segments`` must
        divide ``periods``."""
        if int(periods) % int(segments):
            raise ValueError(f"segments={segments} must divide the period k={periods} for the {self.name} integrator.")

    def segment_flow(self, system, params, x, t0, periods: int, segments: int, s):
        """Segment ``s`` of ``periods`` forcing periods cut into ``segments`` equal pieces
        (multiple shooting, :mod:`jaxgear.shooting._solve`): the flow of one state
        ``x (dim,)`` from ``t0 + s periods T / segments`` over ``periods T / segments``,
        ``(dim,)``, differentiable both ways. ``s`` is a scalar, possibly traced; the
        split is one :meth:`check_segments` accepts. Here :meth:`flow` over
        ``periods / segments`` whole periods."""
        per = int(periods) // int(segments)
        s = jnp.asarray(s, jnp.float64)  # segment index as a time factor
        return self.flow(system, params, x, t0 + s * per * system.period(params), per)

    @property
    @abc.abstractmethod
    def crossing_stepper(self) -> AbstractFixedStep:
        """The fixed-step integrator that brackets and locates section crossings."""

    def to_dict(self) -> dict[str, Any]:
        """The integrator's settings (JSON-able; :func:`integrator_from_dict` rebuilds it)."""
        return {"type": self.name}

    def refined(self) -> AbstractIntegrator:
        """The same integrator with its error about 16 times smaller (half the step of a
        fourth-order method): what a result's label uncertainty is measured against."""
        raise NotImplementedError(f"{type(self).__name__} does not define refined()")


class AbstractFixedStep(AbstractIntegrator):
    """A one-step method with ``steps_per_period`` equal steps per forcing period.

    Subclasses define :meth:`step`; advancing, sampling and section crossings are built
    on it. ``h = T / steps_per_period`` in the system's time unit.
    """

    steps_per_period: eqx.AbstractVar[int]

    @abc.abstractmethod
    def step(self, system, params, t, Y, h):
        """One step of size ``h`` from time ``t`` for a batch ``Y (dim, n)``.

        ``t`` and ``h`` are scalars (one clock for the batch) or ``(n,)`` arrays (one
        per lane, as when a section crossing is located inside a step).
        """

    @property
    def crossing_stepper(self) -> AbstractFixedStep:
        return self

    def check_segments(self, periods: int, segments: int) -> None:
        """``segments`` must divide the ``periods * steps_per_period`` steps (segments of
        whole steps on the step grid of ``P^periods``)."""
        n = int(self.steps_per_period) * int(periods)
        if n % int(segments):
            raise ValueError(f"segments={segments} must divide the {n} steps of a P-{periods} orbit "
                             f"({self.steps_per_period} steps per period).")

    def segment_flow(self, system, params, x, t0, periods: int, segments: int, s):
        """``periods * steps_per_period / segments`` steps from ``t0 + s n h`` (``n`` steps
        per segment, ``h = T / steps_per_period``): the composed segments are the steps of
        ``P^periods``. The pure-JAX steps, differentiable both ways."""
        T = system.period(params)
        n = int(self.steps_per_period) * int(periods) // int(segments)
        h = T / self.steps_per_period
        s = jnp.asarray(s, jnp.float64)  # segment index as a time factor
        return AbstractFixedStep.advance_steps(self, system, params, x[:, None], t0 + s * n * h, n, h)[:, 0]

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.name, "steps_per_period": int(self.steps_per_period)}

    def refined(self) -> AbstractFixedStep:
        """Twice the steps per period (a fourth-order method's error / 16)."""
        return dataclasses.replace(self, steps_per_period=2 * int(self.steps_per_period))

    def advance(self, system, params, Y, t0, periods: int, n_active=None):
        """``periods`` forcing periods of ``steps_per_period`` steps each. The step times of
        every period are ``t0 + i h`` (``i < steps_per_period``): the forcing is
        ``T``-periodic, so each period repeats the same stage times (and a compiled
        kernel can tabulate them once)."""
        T = system.period(params)
        return self.advance_steps(system, params, Y, t0, int(self.steps_per_period), T / self.steps_per_period,
                                  int(periods))

    def advance_steps(self, system, params, Y, t0, n_steps: int, h, repeats: int = 1):
        """``repeats`` times ``n_steps`` steps of size ``h`` from ``t0`` on ``Y (dim, n)``
        (each repeat from the same ``t0``), chunked when large.

        A batch larger than :func:`chunk_lanes` is cut into equal chunks that run one
        after the other, each through all its steps, inside the same computation: a
        chunk's working set (the state and the stages) stays in the last-level cache
        instead of streaming through main memory at every stage. Each lane's arithmetic
        is unchanged, so the result is bit-for-bit that of the unchunked loop.
        """
        dim, n = Y.shape
        chunk = chunk_lanes(dim)

        def one_pass(_, Yb):
            return jax.lax.fori_loop(0, n_steps, lambda i, Z: self.step(system, params, t0 + _as_float(i) * h, Z, h), Yb)

        def loop(Yb):
            return jax.lax.fori_loop(0, int(repeats), one_pass, Yb) if repeats > 1 else one_pass(0, Yb)

        if n <= chunk:
            return loop(Y)
        n_chunks = -(-n // chunk)
        per_chunk = -(-n // n_chunks)
        size = min(n, -(-per_chunk // 8) * 8)  # equal chunks of whole SIMD vectors

        def one_chunk(i, out):
            start = jnp.minimum(i * size, n - size)
            Yb = loop(jax.lax.dynamic_slice_in_dim(Y, start, size, axis=1))
            return jax.lax.dynamic_update_slice_in_dim(out, Yb, start, axis=1)

        return jax.lax.fori_loop(0, n_chunks, one_chunk, Y)

    def trajectory(self, system, params, Y, t0, periods: int, samples_per_period: int):
        T = system.period(params)
        s = int(samples_per_period)
        m = int(periods) * s
        sub = -(-int(self.steps_per_period) // s)  # whole steps between samples
        h = T / (sub * s)
        ts = t0 + T * jnp.arange(m + 1, dtype=jnp.float64) / s

        def one_sample(Z, i):
            t_start = t0 + _as_float(i) * (sub * h)
            Z = jax.lax.fori_loop(0, sub, lambda j, W: self.step(system, params, t_start + _as_float(j) * h, W, h), Z)
            return Z, Z

        _, Ys = jax.lax.scan(one_sample, Y, jnp.arange(m))
        return ts, jnp.concatenate([Y[None], Ys], axis=0)


# Working set of one chunk of the step loop (state, three stages and the new state, 5
# arrays of dim x chunk float64), sized for a shared last-level cache of >= 16 MiB.
# Measured on a 2-core AMD EPYC (32 MiB L3), reduced model, 10^6 cells: 22.7 ns per
# step per cell unchunked, 6.0 ns with chunks of 65,536-100,000 cells, 9.8 ns with
# 32,768 (each stage is one multithreaded XLA loop whose start-up cost then shows).
_CHUNK_BYTES = 16 * 2**20


def _as_float(i):
    """A loop counter as a float64 scalar (step times are float64; no implicit promotion)."""
    return jnp.asarray(i, jnp.float64)


def chunk_lanes(dim: int) -> int:
    """Largest number of lanes :meth:`AbstractFixedStep.advance_steps` runs in one piece."""
    return max(4096, _CHUNK_BYTES // (5 * 8 * int(dim)))
