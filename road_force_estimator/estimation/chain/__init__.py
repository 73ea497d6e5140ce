"""The paper's differentiator chain: per channel a Levant differentiator (:mod:`.differentiator`:
the paper's explicit Euler and our schemes), MODEL.md's reconstruction from its outputs, one
sample at a time (:class:`.core.ChainCore`, the core of ``observer.discretization`` = a
scheme), and the zero-phase offline form (:mod:`.zero_phase`).
"""
from road_force_estimator.estimation.chain.core import ChainCore
from road_force_estimator.estimation.chain.differentiator import SCHEMES

__all__ = ['ChainCore', 'SCHEMES']
