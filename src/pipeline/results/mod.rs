//! What a solved trial is worth and where it goes: its report ([`report`]), whether its joint
//! angles are a person's ([`plausibility`]), its verdict ([`verdict`]: ok, suspect or failed),
//! and export to OpenSim ([`export`]: `.mot` motions, scaled `.osim` models).

pub mod export;
pub mod plausibility;
pub mod report;
pub mod verdict;
