//! thruster-sim: a 6-DOF underwater vehicle simulator.
