"""vo3d-opt"""
