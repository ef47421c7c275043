# core/proto: the wire codec (docs/PROTOCOL.md), portable C99, also in the
# board firmware. Ground.
proto_LIBS :=
