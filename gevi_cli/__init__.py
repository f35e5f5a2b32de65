"""gevi: offline stereo / stereo-inertial odometry (GeVI, CurrentFeature Odometry) and its evaluation."""

__version__ = "0.1.0"
