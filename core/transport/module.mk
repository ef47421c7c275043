# core/transport: frames on the wire, UDP or raw Ethernet (AF_PACKET), and the
# clock. Uses common, proto.
transport_LIBS :=
