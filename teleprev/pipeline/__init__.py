"""Human motion to robot commands: one pure pipeline step for live recording and offline replay alike."""
