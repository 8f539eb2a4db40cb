"""Finger models: geometry, coupled kinematics, statics with tendon elasticity, planning."""
