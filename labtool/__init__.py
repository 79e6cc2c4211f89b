"""labtool: the software of the STB-216 cam-follower test stand."""
__version__ = "0.1.0"
