//! Scenarios, the closed-loop episode runner, the success test and the failure causes.
