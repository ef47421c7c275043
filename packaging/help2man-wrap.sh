#!/bin/sh
# help2man-wrap.sh: runs $VMAC_H2M_PROGRAM with the arguments help2man gives
# (--help, --version), its "usage:" spelt "Usage:" as help2man looks for it,
# so that the man page has a SYNOPSIS (packaging/package.mk, the man pages).
"$VMAC_H2M_PROGRAM" "$@" | sed '1s/^usage:/Usage:/'
