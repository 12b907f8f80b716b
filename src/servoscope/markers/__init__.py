"""servoscope.markers"""
