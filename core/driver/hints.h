/* What Home Assistant makes of a declaration (hints.c owns it): the kind
 * of a variable or param, the device classes each HA platform accepts,
 * and the load-time check of the hint fields device_class, state_class,
 * precision, entity_category and enabled_by_default (docs/DRIVERS.md,
 * "Home Assistant"). Pure functions on the description JSON; any thread. */
#ifndef VMAC_DRIVER_HINTS_H
#define VMAC_DRIVER_HINTS_H

#include <jansson.h>
#include <stddef.h>

/* The kind of a declaration (a variable's or param's object of the
 * description): 'n' number, 'b' boolean, 's' string, from default, values,
 * min, max, unit and a device_class only one kind takes; '?' when none
 * says (the value will). */
char vmac_hints_kind(const json_t *decl);

/* Whether HA's platform component ("sensor", "binary_sensor", "number",
 * "switch", "button", "event") takes device class dc with unit (vmac's
 * spelling, NULL: none). */
int vmac_hints_fits(const char *component, const char *dc, const char *unit);

/* vmac's unit in HA's spelling (degC -> °C, degF -> °F, l -> L). */
const char *vmac_hints_ha_unit(const char *unit);

/* Check the hints of every variable and param of a description (the object
 * drv_describe makes) and fill in the defaults a unit gives where the
 * declaration says nothing: 0, or -1 with err naming the field
 * ("FILE: manifest: params.NAME.FIELD: ..."). */
int vmac_hints_apply(json_t *describe, const char *file, char *err, size_t errlen);

#endif
