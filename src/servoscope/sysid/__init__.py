"""servoscope.sysid"""
