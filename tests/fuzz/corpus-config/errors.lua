slice_us = -1
