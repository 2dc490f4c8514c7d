"""lonlib.ddpg: the DDPG local search, its learners, nets, random streams and devices."""
