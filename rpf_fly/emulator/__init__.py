"""The emulators of the dry run: the fake Crazyradio link driver, the simulated Crazyflie firmware and world,
the NatNet server and the simulated mocap. Nothing here runs in a real flight; see docs/radio.md and docs/mocap.md."""
