"""The outer loop: policy search (docs/method.md section 5).

Drake-free math: ``policy_search`` (the ask/tell methods).
Drake side: ``rollout`` (the rollout runner that resets and simulates the diagram).
"""
