# core/mqtt: vmacd's MQTT client (docs/MQTT.md; mqtt_internal.h says which file
# owns what), Sparkplug B payloads made by protoc-c, and the site view (site.c)
# that the API and `vmac site` share. Uses host, loader, config, common.
mqtt_EXTRA := $(OBJ)/gen/sparkplug_b.pb-c.o
mqtt_LIBS  := $(call pkg_libs,libmosquitto libprotobuf-c jansson) -lpthread -lm
