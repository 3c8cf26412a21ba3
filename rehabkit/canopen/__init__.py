"""Robots on a CAN bus of CANopen drives (CiA 301, the CiA 402 drive profile): the drive state machine first."""
