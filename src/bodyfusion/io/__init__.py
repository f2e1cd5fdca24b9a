"""Readers: IMU and truth CSVs (units, axes, timestamp policies, sanity checks), GNSS fixes
(CSV, NMEA), GetSensorData phone logs. Every bad input is one line naming the file and line."""
