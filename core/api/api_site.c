/* GET /api/site (docs/API.md): the site view vmacd keeps from every host's
 * native MQTT topics on its broker (core/mqtt/site.h), read-only; with MQTT
 * off, {"enabled": false}. */
#include "http_internal.h"

#include "../mqtt/site.h"

enum MHD_Result http_site(struct vmac_http *h, struct MHD_Connection *c, const struct conn *k)
{
	struct vmac_site *site = atomic_load(&h->site);
	json_t *body;
	(void)k;
	if (!site)
		return http_reply(
		    c, MHD_HTTP_OK,
		    json_pack("{s:b, s:s}", "enabled", 0, "why", "MQTT is off (no mqtt_url): no site view"));
	body = vmac_site_json(site);
	if (!body)
		return http_reply(c, MHD_HTTP_INTERNAL_SERVER_ERROR, http_error_body("out of memory"));
	return http_reply(c, MHD_HTTP_OK, body);
}
