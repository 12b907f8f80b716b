"""servoscope.campaign"""
