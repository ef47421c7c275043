# core/common: what several layers speak without knowing each other (values,
# errors, names, addresses, paths, whole files, the SPSC ring, histograms). Ground.
common_LIBS := -lpthread
