/* Home Assistant hints of a driver's declarations: the device classes,
 * units and state classes HA accepts per platform, checked at load against
 * what a driver declares, and the defaults a unit gives (docs/DRIVERS.md,
 * "Home Assistant"; docs/MQTT.md, "Conformance: Home Assistant", cites
 * the HA source of every table here and the commit it was read at).
 *
 * TABLES
 *
 * SENSOR_CLASSES is HA's homeassistant/components/sensor/const.py:
 * DEVICE_CLASS_UNITS (units, '|'-separated, "-" for no unit; NULL: any,
 * as monetary, which has no entry) and DEVICE_CLASS_STATE_CLASSES (a mask
 * of SC_*). Its numeric classes are also the number platform's
 * (number/const.py: NumberDeviceClass and a DEVICE_CLASS_UNITS of its
 * own), except where `number` is 0: temperature_delta is no
 * NumberDeviceClass, and HA's MQTT number refuses a config naming it. A
 * value that becomes a number or a sensor must satisfy both tables, so the
 * units here are those both accept, in the HA releases read (an HA that
 * warns about a unit counts): mVA and kVA, inH₂O and MCF, which only newer
 * releases know, and mPa, which none has, are left out. date, enum and
 * timestamp take no unit and no state class.
 *
 * DEFAULTS
 *
 * Filled into the description (so GET /api/drivers/NAME/manifest shows
 * them and the MQTT profiles read one place): from the unit, a device
 * class, a precision and state_class "measurement" where the class takes
 * it; a string with values read as a sensor is an enum (mqtt_ha.c). */
#include "hints.h"

#include <math.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

enum { SC_M = 1, SC_T = 2, SC_I = 4, SC_ALL = 7 };

struct sensor_class {
	const char *name;
	const char *units; /* '|'-separated, "-" = no unit; NULL: any */
	unsigned states;
	int number; /* 1: a NumberDeviceClass too */
};

#define ENERGY_UNITS "J|kJ|MJ|GJ|mWh|Wh|kWh|MWh|GWh|TWh|cal|kcal|Mcal|Gcal"
#define PRESSURE_UNITS "Pa|kPa|hPa|bar|cbar|mbar|mmHg|inHg|psi"
#define SPEED_UNITS "Beaufort|ft/s|in/s|km/h|kn|m/s|mph|mm/s"
#define FLUX_UNITS "in/d|in/h|mm/d|mm/h"
#define VOLUME_UNITS "L|mL|m³|ft³|CCF|gal|fl. oz."
#define UGM3 "µg/m³"

static const struct sensor_class SENSOR_CLASSES[] = {
    {"apparent_power", "VA", SC_M, 1},
    {"aqi", "-", SC_M, 1},
    {"area", "m²|cm²|km²|mm²|in²|ft²|yd²|mi²|ac|ha", SC_ALL, 1},
    {"atmospheric_pressure", PRESSURE_UNITS, SC_M, 1},
    {"battery", "%", SC_M, 1},
    {"blood_glucose_concentration", "mg/dL|mmol/L", SC_M, 1},
    {"carbon_monoxide", "ppm", SC_M, 1},
    {"carbon_dioxide", "ppm", SC_M, 1},
    {"conductivity", "S/cm|mS/cm|µS/cm", SC_M, 1},
    {"current", "A|mA", SC_M, 1},
    {"data_rate", "bit/s|kbit/s|Mbit/s|Gbit/s|B/s|kB/s|MB/s|GB/s|KiB/s|MiB/s|GiB/s", SC_M, 1},
    {"data_size", "bit|kbit|Mbit|Gbit|B|kB|MB|GB|TB|PB|EB|ZB|YB|KiB|MiB|GiB|TiB|PiB|EiB|ZiB|YiB", SC_ALL, 1},
    {"distance", "mm|cm|m|km|in|ft|yd|mi|nmi", SC_ALL, 1},
    {"duration", "d|h|min|s|ms", SC_ALL, 1},
    {"energy", ENERGY_UNITS, SC_T | SC_I, 1},
    {"energy_distance", "kWh/100km|mi/kWh|km/kWh", SC_M, 1},
    {"energy_storage", ENERGY_UNITS, SC_M, 1},
    {"frequency", "Hz|kHz|MHz|GHz", SC_M, 1},
    {"gas", "m³|ft³|CCF", SC_T | SC_I, 1},
    {"humidity", "%", SC_M, 1},
    {"illuminance", "lx", SC_M, 1},
    {"irradiance", "W/m²|BTU/(h⋅ft²)", SC_M, 1},
    {"moisture", "%", SC_M, 1},
    {"monetary", NULL, SC_T, 1},
    {"nitrogen_dioxide", UGM3, SC_M, 1},
    {"nitrogen_monoxide", UGM3, SC_M, 1},
    {"nitrous_oxide", UGM3, SC_M, 1},
    {"ozone", UGM3, SC_M, 1},
    {"ph", "-", SC_M, 1},
    {"pm1", UGM3, SC_M, 1},
    {"pm10", UGM3, SC_M, 1},
    {"pm25", UGM3, SC_M, 1},
    {"power_factor", "%|-", SC_M, 1},
    {"power", "W|kW|MW|GW|TW", SC_M, 1},
    {"precipitation", "cm|in|mm", SC_ALL, 1},
    {"precipitation_intensity", FLUX_UNITS, SC_M, 1},
    {"pressure", PRESSURE_UNITS, SC_M, 1},
    {"reactive_power", "var", SC_M, 1},
    {"signal_strength", "dB|dBm", SC_M, 1},
    {"sound_pressure", "dB|dBA", SC_M, 1},
    {"speed", SPEED_UNITS "|" FLUX_UNITS, SC_M, 1},
    {"sulphur_dioxide", UGM3, SC_M, 1},
    {"temperature", "°C|°F|K", SC_M, 1},
    {"temperature_delta", "°C|°F|K", SC_M, 0},
    {"volatile_organic_compounds", UGM3, SC_M, 1},
    {"volatile_organic_compounds_parts", "ppm|ppb", SC_M, 1},
    {"voltage", "V|mV|µV|kV|MV", SC_M, 1},
    {"volume", VOLUME_UNITS, SC_T | SC_I, 1},
    {"volume_flow_rate", "m³/h|ft³/min|L/min|gal/min|mL/s|L/h|L/s|m³/s", SC_M, 1},
    {"volume_storage", VOLUME_UNITS, SC_M, 1},
    {"water", "m³|ft³|CCF|gal|L", SC_T | SC_I, 1},
    {"weight", "kg|g|mg|µg|oz|lb|st", SC_ALL, 1},
    {"wind_direction", "°", 0, 1},
    {"wind_speed", SPEED_UNITS, SC_M, 1},
};

/* Non-numeric sensor classes: strings, no unit, no state class. */
static const char *const SENSOR_TEXT_CLASSES[] = {"date", "enum", "timestamp", NULL};

/* homeassistant/components/binary_sensor/__init__.py, BinarySensorDeviceClass. */
static const char *const BINARY_CLASSES[] = {"battery",
                                             "battery_charging",
                                             "carbon_monoxide",
                                             "cold",
                                             "connectivity",
                                             "door",
                                             "garage_door",
                                             "gas",
                                             "heat",
                                             "light",
                                             "lock",
                                             "moisture",
                                             "motion",
                                             "moving",
                                             "occupancy",
                                             "opening",
                                             "plug",
                                             "power",
                                             "presence",
                                             "problem",
                                             "running",
                                             "safety",
                                             "smoke",
                                             "sound",
                                             "tamper",
                                             "update",
                                             "vibration",
                                             "window",
                                             NULL};
/* switch/__init__.py SwitchDeviceClass; button/__init__.py ButtonDeviceClass; event/__init__.py
 * EventDeviceClass. */
static const char *const SWITCH_CLASSES[] = {"outlet", "switch", NULL};
static const char *const BUTTON_CLASSES[] = {"identify", "restart", "update", NULL};
static const char *const EVENT_CLASSES[] = {"doorbell", "button", "motion", NULL};

/* What a unit gives where the declaration says nothing (vmac's spelling). */
static const struct unit_default {
	const char *unit;
	const char *device_class; /* NULL: none (no HA class takes it) */
	int precision;
} UNIT_DEFAULTS[] = {
    {"degC", "temperature", 1},  {"degF", "temperature", 1}, {"K", "temperature", 1}, {"l", "volume_storage", 1},
    {"mL", "volume_storage", 0}, {"s", "duration", 0},       {"ms", "duration", 0},   {"min", "duration", 0},
    {"h", "duration", 1},        {"W", "power", 0},          {"kW", "power", 2},      {"kWh", "energy", 2},
    {"Wh", "energy", 0},         {"V", "voltage", 1},        {"A", "current", 2},     {"Hz", "frequency", 1},
    {"bar", "pressure", 2},      {"kPa", "pressure", 1},     {"rpm", NULL, 0},
};

const char *vmac_hints_ha_unit(const char *unit)
{
	if (!unit)
		return NULL;
	if (strcmp(unit, "degC") == 0)
		return "°C";
	if (strcmp(unit, "degF") == 0)
		return "°F";
	if (strcmp(unit, "l") == 0)
		return "L";
	return unit;
}

static int in_list(const char *const *list, const char *s)
{
	for (; *list; list++)
		if (strcmp(*list, s) == 0)
			return 1;
	return 0;
}

static const struct sensor_class *sensor_class(const char *dc)
{
	size_t i;
	for (i = 0; i < sizeof(SENSOR_CLASSES) / sizeof(SENSOR_CLASSES[0]); i++)
		if (strcmp(SENSOR_CLASSES[i].name, dc) == 0)
			return &SENSOR_CLASSES[i];
	return NULL;
}

/* Whether a '|'-separated list holds unit ("-" for none). */
static int unit_in(const char *units, const char *unit)
{
	const char *want = unit ? unit : "-", *p = units;
	size_t n = strlen(want);
	while (p && *p) {
		const char *end = strchr(p, '|');
		size_t len = end ? (size_t)(end - p) : strlen(p);
		if (len == n && strncmp(p, want, n) == 0)
			return 1;
		p = end ? end + 1 : NULL;
	}
	return 0;
}

static int unit_ok(const struct sensor_class *c, const char *unit)
{
	return !c->units || unit_in(c->units, vmac_hints_ha_unit(unit));
}

int vmac_hints_fits(const char *component, const char *dc, const char *unit)
{
	const struct sensor_class *c;
	if (strcmp(component, "binary_sensor") == 0)
		return in_list(BINARY_CLASSES, dc);
	if (strcmp(component, "switch") == 0)
		return in_list(SWITCH_CLASSES, dc);
	if (strcmp(component, "button") == 0)
		return in_list(BUTTON_CLASSES, dc);
	if (strcmp(component, "event") == 0)
		return in_list(EVENT_CLASSES, dc);
	if (strcmp(component, "sensor") == 0 && in_list(SENSOR_TEXT_CLASSES, dc))
		return !unit;
	if (strcmp(component, "sensor") != 0 && strcmp(component, "number") != 0)
		return 0; /* select, text: no device class */
	c = sensor_class(dc);
	return c && unit_ok(c, unit) && (c->number || strcmp(component, "number") != 0);
}

char vmac_hints_kind(const json_t *decl)
{
	json_t *def = json_object_get(decl, "default");
	const char *dc = json_string_value(json_object_get(decl, "device_class"));
	if (json_object_get(decl, "values") || json_is_string(def))
		return 's';
	if (json_is_boolean(def))
		return 'b';
	if (json_is_number(def) || json_object_get(decl, "min") || json_object_get(decl, "max") ||
	    json_object_get(decl, "unit"))
		return 'n';
	if (dc && (in_list(BINARY_CLASSES, dc) || in_list(SWITCH_CLASSES, dc)) && !sensor_class(dc))
		return 'b';
	if (dc && in_list(SENSOR_TEXT_CLASSES, dc))
		return 's';
	if (dc && sensor_class(dc))
		return 'n';
	return '?';
}

/* The accepted values of a list, for a message: "a, b, c". */
static void list_text(char *out, size_t outlen, const char *const *list)
{
	size_t n = 0;
	out[0] = 0;
	for (; *list && n + 1 < outlen; list++)
		n += (size_t)snprintf(out + n, outlen - n, "%s%s", n ? ", " : "", *list);
}

static void units_text(char *out, size_t outlen, const char *units)
{
	size_t i, n = 0;
	for (i = 0; units[i] && n + 6 < outlen; i++) {
		if (units[i] == '|') {
			out[n++] = ',';
			out[n++] = ' ';
		} else {
			out[n++] = units[i];
		}
	}
	out[n] = 0;
	if (strcmp(out, "-") == 0)
		snprintf(out, outlen, "no unit");
}

static const char *const STATE_NAMES[] = {"measurement", "total", "total_increasing"};

static unsigned state_bit(const char *s)
{
	unsigned i;
	for (i = 0; i < 3; i++)
		if (strcmp(s, STATE_NAMES[i]) == 0)
			return 1u << i;
	return 0;
}

#define BAD(...)                                                                                                       \
	do {                                                                                                           \
		int n_ = snprintf(err, errlen, "%s: manifest: %s.%s.", file, table, name);                             \
		if (n_ > 0 && (size_t)n_ < errlen)                                                                     \
			snprintf(err + n_, errlen - (size_t)n_, __VA_ARGS__);                                          \
		return -1;                                                                                             \
	} while (0)

/* device_class of a declaration of kind kind, settable or not. */
static int check_device_class(json_t *decl, const char *dc, char kind, int settable, const char *file,
                              const char *table, const char *name, char *err, size_t errlen)
{
	const char *unit = json_string_value(json_object_get(decl, "unit"));
	const struct sensor_class *c;
	char accepted[700];
	if (kind == 'b') {
		if (in_list(BINARY_CLASSES, dc) || (settable && in_list(SWITCH_CLASSES, dc)))
			return 0;
		list_text(accepted, sizeof(accepted), BINARY_CLASSES);
		BAD("device_class: \"%s\" is not a device class of a %s (HA accepts %s%s)", dc,
		    settable ? "switch or binary_sensor" : "binary_sensor", accepted,
		    settable ? "; a switch: outlet, switch" : "");
	}
	if (kind == 's') {
		if (!in_list(SENSOR_TEXT_CLASSES, dc))
			BAD("device_class: \"%s\" is not a device class of a text value (HA's sensor accepts enum, "
			    "timestamp, date)",
			    dc);
		if (strcmp(dc, "enum") == 0 && !json_is_array(json_object_get(decl, "values")))
			BAD("device_class: \"enum\" needs values (HA's options)");
		return 0;
	}
	if (kind == '?')
		BAD("device_class: \"%s\": the declaration does not say whether the value is a number, a boolean "
		    "or a string (give it a default, a unit or values)",
		    dc);
	if (!(c = sensor_class(dc)))
		BAD("device_class: \"%s\" is not a device class of a numeric sensor or number", dc);
	if (settable && !c->number)
		BAD("device_class: \"%s\" is a sensor's class only; a settable value is HA's number, which refuses "
		    "it (number/const.py NumberDeviceClass)",
		    dc);
	if (!unit_ok(c, unit)) {
		units_text(accepted, sizeof(accepted), c->units);
		if (unit)
			BAD("device_class: \"%s\" does not take unit \"%s\" (HA accepts %s)", dc, unit, accepted);
		BAD("device_class: \"%s\" needs a unit (HA accepts %s)", dc, accepted);
	}
	return 0;
}

/* The hints of one declaration; defaults from its unit filled in. */
static int check_decl(json_t *decl, int settable, const char *file, const char *table, const char *name, char *err,
                      size_t errlen)
{
	json_t *v, *min = json_object_get(decl, "min"), *max = json_object_get(decl, "max");
	const char *unit = json_string_value(json_object_get(decl, "unit"));
	const char *dc = NULL, *sc = NULL;
	char kind = vmac_hints_kind(decl);
	size_t i;
	if (!json_is_object(decl))
		return 0;
	if ((v = json_object_get(decl, "device_class")) != NULL) {
		if (!json_is_string(v))
			BAD("device_class must be a string (a Home Assistant device class)");
		dc = json_string_value(v);
		if (check_device_class(decl, dc, kind, settable, file, table, name, err, errlen))
			return -1;
	}
	if ((v = json_object_get(decl, "state_class")) != NULL) {
		const struct sensor_class *c = dc ? sensor_class(dc) : NULL;
		if (!json_is_string(v) || !state_bit(json_string_value(v)))
			BAD("state_class must be \"measurement\", \"total\" or \"total_increasing\"");
		sc = json_string_value(v);
		if (kind != 'n')
			BAD("state_class: only a number has one");
		if (c && !(c->states & state_bit(sc))) {
			char accepted[80] = "";
			size_t n = 0;
			unsigned b;
			for (b = 0; b < 3; b++)
				if (c->states & (1u << b))
					n += (size_t)snprintf(accepted + n, sizeof(accepted) - n, "%s%s", n ? ", " : "",
					                      STATE_NAMES[b]);
			BAD("state_class: device class \"%s\" does not take \"%s\" (HA accepts %s)", dc, sc,
			    n ? accepted : "none");
		}
	}
	if ((v = json_object_get(decl, "precision")) != NULL) {
		double p = json_number_value(v);
		if (!json_is_number(v) || p != floor(p) || p < 0 || p > 6)
			BAD("precision must be a whole number 0..6 (decimals shown, and kept when published)");
		if (kind != 'n')
			BAD("precision: only a number has one");
	}
	if ((v = json_object_get(decl, "entity_category")) != NULL) {
		const char *ec = json_string_value(v);
		if (!ec || (strcmp(ec, "config") && strcmp(ec, "diagnostic")))
			BAD("entity_category must be \"config\" or \"diagnostic\"");
		if (!settable && strcmp(ec, "config") == 0)
			BAD("entity_category: \"config\" is for settings; a read-only value is a sensor or "
			    "binary_sensor, which HA refuses in that category (use \"diagnostic\")");
	}
	if ((v = json_object_get(decl, "enabled_by_default")) != NULL && !json_is_boolean(v))
		BAD("enabled_by_default must be true or false");
	if ((v = json_object_get(decl, "step")) != NULL && (!json_is_number(v) || !(json_number_value(v) >= 0.001)))
		BAD("step must be a number of at least 0.001 (HA's number refuses less)");
	if (json_is_number(min) && json_is_number(max) && !(json_number_value(min) < json_number_value(max)))
		BAD("min must be less than max (HA's number refuses min >= max)");
	if (kind != 'n' || !unit)
		return 0;
	for (i = 0; i < sizeof(UNIT_DEFAULTS) / sizeof(UNIT_DEFAULTS[0]); i++)
		if (strcmp(UNIT_DEFAULTS[i].unit, unit) == 0) {
			if (!dc && UNIT_DEFAULTS[i].device_class) {
				dc = UNIT_DEFAULTS[i].device_class;
				json_object_set_new(decl, "device_class", json_string(dc));
			}
			if (!json_object_get(decl, "precision"))
				json_object_set_new(decl, "precision", json_integer(UNIT_DEFAULTS[i].precision));
			break;
		}
	if (!sc) {
		const struct sensor_class *c = dc ? sensor_class(dc) : NULL;
		if (!c || (c->states & SC_M))
			json_object_set_new(decl, "state_class", json_string("measurement"));
	}
	return 0;
}
#undef BAD

int vmac_hints_apply(json_t *describe, const char *file, char *err, size_t errlen)
{
	const char *name;
	json_t *decl;
	json_object_foreach(json_object_get(describe, "variables"), name, decl)
	{
		if (check_decl(decl, json_is_true(json_object_get(decl, "set")), file, "variables", name, err, errlen))
			return -1;
	}
	json_object_foreach(json_object_get(describe, "params"), name, decl)
	{
		if (check_decl(decl, 1, file, "params", name, err, errlen))
			return -1;
	}
	return 0;
}
