"""Splitting a batch across several CPU devices: one chunk of members per device.

XLA runs a vmapped batch on one core. When JAX has several CPU devices (one per core, asked for
before JAX starts), :mod:`gnipy.ensembles` splits a batch's members into one chunk per device
with :func:`jax.shard_map`, each chunk running on its own core without communication.
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp

__all__ = ["member_devices", "shard_map", "pad_members"]


def member_devices() -> tuple:
    """The CPU devices that an XLA batch is split across: JAX's devices when its default backend is
    the CPU and it has several, else `()`.

    JAX starts with one CPU device. Ask for one per core before JAX first computes anything, with
    `jax.config.update("jax_num_cpu_devices", n)` or the environment variable
    `JAX_NUM_CPU_DEVICES=n`; the members of a batch on XLA are then split into one chunk per device
    (:func:`jax.shard_map`), each chunk running on its own core. (A library should not set this
    process-wide option for its user: it changes every JAX program of the process.)
    """
    if jax.default_backend() != "cpu":
        return ()
    devices = jax.devices()
    return tuple(devices) if len(devices) > 1 else ()


def shard_map():
    """`jax.shard_map` without its replication check (`jax.experimental.shard_map` before jax 0.6)."""
    try:
        return functools.partial(jax.shard_map, check_vma=False)
    except AttributeError:  # jax < 0.6
        from jax.experimental.shard_map import shard_map as experimental

        return functools.partial(experimental, check_rep=False)


def pad_members(tree, B: int, to: int):
    """Each array leaf's member axis (length B) padded to `to` with copies of the last member."""
    if to == B:
        return tree
    return jax.tree_util.tree_map(
        lambda a: jnp.concatenate([a, jnp.repeat(a[-1:], to - B, axis=0)]) if eqx.is_array(a) else a, tree)
