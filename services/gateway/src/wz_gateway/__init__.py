"""Gateway: stored trajectories, alerts and devices over REST, and a WZDx 4.2 device feed."""
