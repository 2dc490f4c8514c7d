"""lonlib.sb3: Stable-Baselines3's TD3, SAC and DDPG as local searches: the parameter
conversion (lonlib's forward equals SB3's), deterministic searches under lonlib's judging
rules, a basin-hopping run with an SB3 search killed and resumed, the missing extra."""
