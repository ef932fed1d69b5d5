"""sbmpc: Sampling-Based Model Predictive Control for skid-steered robots on hilly terrain."""
__version__ = "0.1.0"
