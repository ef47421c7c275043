/* Unit tests of the Home Assistant hints of a driver's declarations
 * (core/driver/hints.c): what HA refuses is a load error naming the field,
 * the defaults a unit gives land in the description, and a real load
 * carries both. */
#include <check.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "../../core/driver/driver.h"
#include "../../core/driver/hints.h"
#include "check_main.h"

/* vmac_hints_apply on {TABLE: {NAME: DECL}}; DECL is JSON. 0 or -1, err. */
static int apply(const char *table, const char *decl_json, json_t **out, char *err, size_t errlen)
{
	json_error_t jerr;
	json_t *decl = json_loads(decl_json, 0, &jerr), *desc;
	int rc;
	ck_assert_msg(decl != NULL, "bad JSON in the test: %s", decl_json);
	desc = json_pack("{s:{s:o}}", table, "x", decl);
	rc = vmac_hints_apply(desc, "t.lua", err, errlen);
	if (out)
		*out = json_incref(json_object_get(json_object_get(desc, table), "x"));
	json_decref(desc);
	return rc;
}

static void refused(const char *table, const char *decl, const char *want)
{
	char err[400] = "";
	ck_assert_msg(apply(table, decl, NULL, err, sizeof(err)) == -1, "%s %s was accepted (wanted '%s')", table, decl,
	              want);
	ck_assert_msg(strstr(err, want) != NULL, "error '%s' does not say '%s'", err, want);
}

static json_t *accepted(const char *table, const char *decl)
{
	char err[400] = "";
	json_t *out = NULL;
	ck_assert_msg(apply(table, decl, &out, err, sizeof(err)) == 0, "%s %s was refused: %s", table, decl, err);
	return out;
}

START_TEST(what_home_assistant_refuses_names_the_field)
{
	refused("params", "{\"default\": 5, \"unit\": \"l\", \"device_class\": \"temperature\"}",
	        "t.lua: manifest: params.x.device_class: \"temperature\" does not take unit \"l\" (HA accepts °C, °F, "
	        "K)");
	refused("variables",
	        "{\"unit\": \"s\", \"device_class\": \"duration\", \"state_class\": \"total\", "
	        "\"precision\": 7}",
	        "variables.x.precision must be a whole number 0..6");
	refused("variables", "{\"unit\": \"kWh\", \"device_class\": \"energy\", \"state_class\": \"measurement\"}",
	        "variables.x.state_class: device class \"energy\" does not take \"measurement\" (HA accepts total, "
	        "total_increasing)");
	refused("variables", "{\"device_class\": \"enum\"}", "variables.x.device_class: \"enum\" needs values");
	refused("variables", "{\"device_class\": \"doorbell\"}", "does not say whether the value is a number");
	/* Tables checked against HA's source (docs/MQTT.md, "Conformance: Home Assistant"). */
	refused("params", "{\"default\": 1, \"unit\": \"K\", \"device_class\": \"temperature_delta\"}",
	        "params.x.device_class: \"temperature_delta\" is a sensor's class only");
	refused("variables", "{\"unit\": \"kVA\", \"device_class\": \"apparent_power\"}",
	        "does not take unit \"kVA\" (HA accepts VA)");
	refused("variables", "{\"unit\": \"MCF\", \"device_class\": \"volume\", \"state_class\": \"total\"}",
	        "does not take unit \"MCF\"");
	refused("variables", "{\"default\": true, \"entity_category\": \"config\"}", "sensor or binary_sensor");
	refused("variables", "{\"default\": false, \"device_class\": \"outlet\"}",
	        "\"outlet\" is not a device class of a binary_sensor");
	refused("variables", "{\"unit\": \"l\", \"entity_category\": \"config\"}",
	        "variables.x.entity_category: \"config\" is for settings");
	refused("params", "{\"default\": 1, \"entity_category\": \"settings\"}",
	        "params.x.entity_category must be \"config\" or \"diagnostic\"");
	refused("params", "{\"default\": 1, \"step\": 0.0005}", "params.x.step must be a number of at least 0.001");
	refused("params", "{\"default\": 1, \"min\": 5, \"max\": 5}", "params.x.min must be less than max");
	refused("params", "{\"default\": 1, \"enabled_by_default\": \"yes\"}", "enabled_by_default must be true");
	refused("variables", "{\"device_class\": \"temperature\"}", "needs a unit (HA accepts °C, °F, K)");
	refused("variables", "{\"values\": [\"a\"], \"state_class\": \"measurement\"}", "only a number has one");
	refused("variables", "{\"device_class\": 3}", "device_class must be a string");
}
END_TEST

START_TEST(a_unit_gives_defaults_a_declaration_can_override)
{
	json_t *d = accepted("variables", "{\"unit\": \"degC\"}");
	ck_assert_str_eq(json_string_value(json_object_get(d, "device_class")), "temperature");
	ck_assert_str_eq(json_string_value(json_object_get(d, "state_class")), "measurement");
	ck_assert_int_eq((int)json_number_value(json_object_get(d, "precision")), 1);
	json_decref(d);
	d = accepted("params", "{\"default\": 5, \"unit\": \"l\", \"precision\": 0, \"device_class\": \"volume\", "
	                       "\"state_class\": \"total\"}");
	ck_assert_str_eq(json_string_value(json_object_get(d, "device_class")), "volume");
	ck_assert_int_eq((int)json_number_value(json_object_get(d, "precision")), 0);
	json_decref(d);
	d = accepted("variables", "{\"unit\": \"s\"}");
	ck_assert_str_eq(json_string_value(json_object_get(d, "device_class")), "duration");
	json_decref(d);
	/* No HA class takes rpm: a measurement without one. */
	d = accepted("variables", "{\"unit\": \"rpm\"}");
	ck_assert_ptr_null(json_object_get(d, "device_class"));
	ck_assert_str_eq(json_string_value(json_object_get(d, "state_class")), "measurement");
	json_decref(d);
	/* A string or a boolean gets no default; a door is a boolean by its class. */
	d = accepted("variables", "{\"device_class\": \"door\"}");
	ck_assert_int_eq(vmac_hints_kind(d), 'b');
	ck_assert_ptr_null(json_object_get(d, "state_class"));
	json_decref(d);
	d = accepted("variables", "{\"values\": [\"idle\", \"running\"], \"device_class\": \"enum\"}");
	ck_assert_ptr_null(json_object_get(d, "precision"));
	json_decref(d);
	d = accepted("params", "{\"default\": true, \"device_class\": \"outlet\", \"entity_category\": \"config\"}");
	json_decref(d);
}
END_TEST

START_TEST(fits_follows_each_platform)
{
	ck_assert(vmac_hints_fits("sensor", "temperature", "degC"));
	ck_assert(vmac_hints_fits("number", "volume_storage", "l"));
	ck_assert(!vmac_hints_fits("sensor", "temperature", "l"));
	ck_assert(!vmac_hints_fits("number", "enum", NULL));
	ck_assert(vmac_hints_fits("sensor", "enum", NULL));
	ck_assert(vmac_hints_fits("binary_sensor", "door", NULL));
	ck_assert(!vmac_hints_fits("switch", "door", NULL));
	ck_assert(vmac_hints_fits("switch", "outlet", NULL));
	ck_assert(!vmac_hints_fits("select", "enum", NULL));
	ck_assert(vmac_hints_fits("sensor", "temperature_delta", "K"));
	ck_assert(!vmac_hints_fits("number", "temperature_delta", "K"));
	ck_assert(vmac_hints_fits("button", "restart", NULL));
	ck_assert(!vmac_hints_fits("event", "ring", NULL));
	ck_assert(vmac_hints_fits("event", "doorbell", NULL));
	ck_assert_str_eq(vmac_hints_ha_unit("degF"), "°F");
}
END_TEST

/* Through a real load: the error, and the defaults in the description. */
START_TEST(a_load_checks_hints_and_describes_defaults)
{
	struct vmac_driver_limits limits;
	struct vmac_driver *d = NULL;
	char dir[] = "/tmp/vmac-test-hints-XXXXXX", path[64], err[VMAC_DRIVER_ERR_MAX] = "";
	FILE *f;
	json_t *desc;
	memset(&limits, 0, sizeof(limits));
	limits.memory_bytes = 1 << 20;
	limits.instructions = 200000;
	limits.max_level = 10;
	limits.default_level = 4;
	limits.expect_name = "t";
	ck_assert(mkdtemp(dir) != NULL);
	snprintf(path, sizeof(path), "%s/t.lua", dir);
	f = fopen(path, "w");
	ck_assert(f != NULL);
	fputs("return { name = 't', version = '1', io = {}, tick = function() end,\n"
	      "  params = { door_level_l = { default = 5, min = 0, max = 40, unit = 'l', device_class = 'temperature' "
	      "} } }\n",
	      f);
	fclose(f);
	ck_assert_int_ne(vmac_driver_load(path, &limits, &d, err, sizeof(err)), 0);
	ck_assert_msg(strstr(err, "t.lua: manifest: params.door_level_l.device_class: \"temperature\" does not take "
	                          "unit \"l\" (HA accepts °C, °F, K)") != NULL,
	              "load error: %s", err);
	f = fopen(path, "w");
	ck_assert(f != NULL);
	fputs("return { name = 't', version = '1', io = {}, tick = function() end,\n"
	      "  variables = { temp_c = { unit = 'degC' } } }\n",
	      f);
	fclose(f);
	ck_assert_msg(vmac_driver_load(path, &limits, &d, err, sizeof(err)) == 0, "load failed: %s", err);
	desc = json_loads(vmac_driver_describe(d), 0, NULL);
	ck_assert_str_eq(json_string_value(json_object_get(
	                     json_object_get(json_object_get(desc, "variables"), "temp_c"), "device_class")),
	                 "temperature");
	json_decref(desc);
	vmac_driver_free(d);
	unlink(path);
	rmdir(dir);
}
END_TEST

Suite *vmac_test_suite(void)
{
	Suite *s = suite_create("hints");
	TCase *tc = tcase_create("hints");
	tcase_add_test(tc, what_home_assistant_refuses_names_the_field);
	tcase_add_test(tc, a_unit_gives_defaults_a_declaration_can_override);
	tcase_add_test(tc, fits_follows_each_platform);
	tcase_add_test(tc, a_load_checks_hints_and_describes_defaults);
	suite_add_tcase(s, tc);
	return s;
}
