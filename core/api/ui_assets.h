/* The web UI's files, built into vmacd (core/api/ui/, embedded at build
 * time by core/api/ui/embed.py). */
#ifndef VMAC_UI_ASSETS_H
#define VMAC_UI_ASSETS_H

#include <stddef.h>

struct vmac_ui_asset {
	const char *name; /* "index.html", "app.js", ... */
	const char *content_type;
	const unsigned char *data;
	size_t len;
};

/* Ends with an entry whose name is NULL. */
extern const struct vmac_ui_asset vmac_ui_assets[];

#endif
