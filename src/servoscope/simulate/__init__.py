"""servoscope.simulate"""
