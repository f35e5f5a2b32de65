"""IMU handling for the stereo-inertial pipeline and `gevi imu`.

``imu_stream``: the IMU on the camera clock (time shift applied), checked, with its noise model;
samples between frames, specific force and gyro increments per frame interval.
``standstill``: detection of a standstill from the IMU and the gravity / gyro-bias estimate over it.
``attitude``: the IMU-only roll/pitch filter of `gevi imu` (gyro + adaptive gravity prior).
"""
