"""servoscope.rig"""
