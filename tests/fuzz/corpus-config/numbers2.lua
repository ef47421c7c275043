slice_us = 0x10
sleep_s = "1e1"
http = "1.2.3.4:65536"
