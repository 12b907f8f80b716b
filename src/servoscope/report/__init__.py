"""servoscope.report"""
