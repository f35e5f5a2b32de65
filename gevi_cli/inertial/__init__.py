"""IMU handling for the stereo-inertial pipeline and `gevi imu`.

``imu_stream``: the IMU on the camera clock (time shift applied), checked, with its noise model;
samples between frames, specific force and gyro increments per frame interval.
``standstill``: detection of a standstill from the IMU and the gravity / gyro-bias estimate over it.
``attitude``: the IMU-only gravity-prior roll/pitch filter (GeVI's ``fusion.mode = 4dof``) and the
baselines of `gevi imu` (gyro-only, complementary filters by time constant).
``velocity_aided``: `gevi imu`'s roll/pitch filter (gyro bias and scale, bounded velocity).
``reference_alignment``: a mocap reference put on the IMU clock and frame from the angular rates.
``vqf_rows``: VQF 6D online and offline (the ``vqf`` package), `gevi imu`'s reference rows.
"""
