"""DDPG as the local search F(theta, omega, e, h): networks, random streams, replay buffers,
the reference and the lean learner, the slot trainer (torch)."""

from lonlib.ddpg.trainer import *  # noqa: F403
