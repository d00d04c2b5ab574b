"""Stage 2, fly it: the SIL flight, the back-seat process, the run's bus and process lifecycle, ArduSub SITL."""
