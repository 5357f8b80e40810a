"""Foundations every layer may use: user errors, vector maths, ray batches, the numba decorator and process-wide runtime tuning."""
