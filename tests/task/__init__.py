"""lonlib.task: simulator, Gymnasium env, controllers, rollout (numpy, compiled), behaviour."""
