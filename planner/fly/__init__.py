"""Stage 2, fly it: what to fly (:mod:`planner.fly.flight`), in the loop (:mod:`planner.fly.sil`) or
on a vehicle's MAVLink port (:mod:`planner.fly.vehicle`), with the back-seat process, the run's
bus and process lifecycle that both use, and ArduSub's SITL firmware to rehearse on."""
