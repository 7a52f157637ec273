"""Export: rollouts as LeRobot v3 datasets (``recorder``, ``merge``), the dataset card, Hub push, report.html, W&B."""
