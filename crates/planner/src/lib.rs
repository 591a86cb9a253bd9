//! The upper virtual-PIT decision layer, the decision package Π and the phase machine.
