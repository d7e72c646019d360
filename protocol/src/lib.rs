//! Message types and services shared by every thrusterd process.
