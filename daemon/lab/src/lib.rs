//! The simulation lab: the demo and the paper's pool experiments. Each starts thrusterd and
//! thruster-sim as processes on a private namespace ([`session`]), drives them through the
//! operator's client and scores the result against the simulator's truth ([`scoring`]).
//! Not part of a vehicle build (thrusterctl's `lab` feature).

pub mod child;
pub mod demo;
pub mod excursion;
pub mod experiment;
mod flags;
pub mod model_truth;
pub mod plot;
pub mod recording;
pub mod scoring;
pub mod seeds;
pub mod session;
pub mod study;
pub mod vehicle;
pub mod water;
