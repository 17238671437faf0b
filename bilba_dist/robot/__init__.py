"""The Franka Panda: kinematics and dynamics terms from Pinocchio, IK."""
