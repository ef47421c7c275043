/* SipHash-2-4: see siphash.h. Two compression rounds per 8-byte word, four
 * finalisation rounds; words and output little-endian, as the paper says. */
#include "siphash.h"

#define ROTL(x, b) (uint64_t)(((x) << (b)) | ((x) >> (64 - (b))))

struct sip {
	uint64_t v0, v1, v2, v3;
};

static uint64_t load64(const uint8_t *p)
{
	uint64_t x = 0;
	int i;
	for (i = 7; i >= 0; i--)
		x = x << 8 | p[i];
	return x;
}

static void store64(uint8_t *p, uint64_t x)
{
	int i;
	for (i = 0; i < 8; i++, x >>= 8)
		p[i] = (uint8_t)x;
}

static void round_(struct sip *s)
{
	s->v0 += s->v1;
	s->v1 = ROTL(s->v1, 13);
	s->v1 ^= s->v0;
	s->v0 = ROTL(s->v0, 32);
	s->v2 += s->v3;
	s->v3 = ROTL(s->v3, 16);
	s->v3 ^= s->v2;
	s->v0 += s->v3;
	s->v3 = ROTL(s->v3, 21);
	s->v3 ^= s->v0;
	s->v2 += s->v1;
	s->v1 = ROTL(s->v1, 17);
	s->v1 ^= s->v2;
	s->v2 = ROTL(s->v2, 32);
}

static void compress(struct sip *s, uint64_t m)
{
	s->v3 ^= m;
	round_(s);
	round_(s);
	s->v0 ^= m;
}

/* Key set-up and every word of msg, the last one with the length. */
static void absorb(struct sip *s, const uint8_t key[VMAC_SIPHASH_KEY_LEN], const uint8_t *msg, size_t len, int wide)
{
	uint64_t k0 = load64(key), k1 = load64(key + 8), last = (uint64_t)len << 56;
	size_t i, full = len - len % 8;
	s->v0 = k0 ^ 0x736f6d6570736575ULL;
	s->v1 = k1 ^ 0x646f72616e646f6dULL;
	s->v2 = k0 ^ 0x6c7967656e657261ULL;
	s->v3 = k1 ^ 0x7465646279746573ULL;
	if (wide)
		s->v1 ^= 0xee;
	for (i = 0; i < full; i += 8)
		compress(s, load64(msg + i));
	for (i = 0; i < len % 8; i++)
		last |= (uint64_t)msg[full + i] << (8 * i);
	compress(s, last);
}

static uint64_t finish(struct sip *s, uint64_t mark)
{
	s->v2 ^= mark;
	round_(s);
	round_(s);
	round_(s);
	round_(s);
	return s->v0 ^ s->v1 ^ s->v2 ^ s->v3;
}

void vmac_siphash24(const uint8_t key[VMAC_SIPHASH_KEY_LEN], const uint8_t *msg, size_t len, uint8_t out[8])
{
	struct sip s;
	absorb(&s, key, msg, len, 0);
	store64(out, finish(&s, 0xff));
}

void vmac_siphash24_128(const uint8_t key[VMAC_SIPHASH_KEY_LEN], const uint8_t *msg, size_t len, uint8_t out[16])
{
	struct sip s;
	absorb(&s, key, msg, len, 1);
	store64(out, finish(&s, 0xee));
	s.v1 ^= 0xdd;
	store64(out + 8, finish(&s, 0));
}
