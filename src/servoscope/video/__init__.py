"""servoscope.video"""
