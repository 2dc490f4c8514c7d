"""The coupled inverted pendulums task: physics, Gymnasium env, reference controllers, the one
rollout that scores every policy, and behaviour descriptors (numpy only, no torch)."""
