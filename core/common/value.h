/* A value that crosses modules: a published variable, a param, an
 * operator's input, a persisted param in the store. Plain data, no
 * dependency: the driver API (core/driver/driver.h) and the store
 * (core/store/store.h) both speak it without knowing each other. */
#ifndef VMAC_VALUE_H
#define VMAC_VALUE_H

#define VMAC_VALUE_STR_MAX 63 /* bytes of a string value */

enum vmac_value_type { VMAC_VALUE_NONE, VMAC_VALUE_NUMBER, VMAC_VALUE_BOOL, VMAC_VALUE_STRING };

struct vmac_value {
	enum vmac_value_type type;
	double number; /* also the boolean (0/1) */
	char str[VMAC_VALUE_STR_MAX + 1];
};

#endif
