# packaging/package.mk: vmac installed (make install, make uninstall), as a
# Debian package (make deb) and that package's test (make test-package);
# docs/SERVICE.md. The files beside this one
# are the service's: the unit (vmacd.service), the settings file
# (vmacd.conf), the user (vmac.sysusers) and the state folder
# (vmac.tmpfiles); debian/ holds the package's own.
#
#   make install [PREFIX=/usr/local] [DESTDIR=]   the programs, their files, man pages, docs, the unit
#   make deb                                      build/deb/vmac_VERSION_ARCH.deb, checked by lintian
#   make test-package                             make deb, dpkg -i, the service's command as its user,
#                                                 the kitchen, dpkg --purge; make install into a folder;
#                                                 then the package in a booted Debian (systemd-nspawn)

PREFIX      ?= /usr/local
DESTDIR     ?=
BINDIR      ?= $(PREFIX)/bin
DATADIR     ?= $(PREFIX)/share/vmac
DOCDIR      ?= $(PREFIX)/share/doc/vmac
MAN1DIR     ?= $(PREFIX)/share/man/man1
# /usr's settings go in /etc, any other prefix's in PREFIX/etc.
SYSCONFDIR  ?= $(if $(filter /usr,$(PREFIX)),/etc,$(PREFIX)/etc)
# Folders systemd reads for PREFIX /usr and /usr/local alike (the Debian
# package says /lib/systemd/system, as Debian 12 wants).
UNITDIR     ?= $(PREFIX)/lib/systemd/system
SYSUSERSDIR ?= $(PREFIX)/lib/sysusers.d
TMPFILESDIR ?= $(PREFIX)/lib/tmpfiles.d

# make deps: help2man makes the man pages from the programs' --help;
# debhelper and dpkg-dev build the package, lintian checks it; the package
# test reads man pages (man-db) and the unit (systemd-analyze, from systemd); mmdebstrap and
# systemd-nspawn (systemd-container) boot a Debian root for it to run under systemd (boot.py).
PACKAGE_DEBS := help2man debhelper dpkg-dev lintian man-db systemd mmdebstrap systemd-container
DEBS += $(PACKAGE_DEBS)

# What the programs read at run time, by path from the root they find
# (core/common/paths.h): the stdlib, the shipped drivers and their
# programmes, luacheck's settings (vmac lint), vmac test's runner and the
# shipped driver tests it runs when given none.
INSTALL_DATA := $(sort $(wildcard stdlib/*.lua scripts/drivers/*.lua scripts/cycles/*/*.lua tests/drivers/*_test.lua)) \
                scripts/luacheckrc $(sort $(wildcard core/vtest/*.lua))
# The LuaLS annotations (scripts/types/) go to DATADIR/types, the folder a
# user's .luarc.json names (docs/DRIVERS.md, "Checking a driver").
INSTALL_TYPES := $(sort $(wildcard scripts/types/*.lua scripts/types/*/*.lua))
INSTALL_DOCS := README.md $(sort $(wildcard docs/*.md))
MAN_PAGES    := $(BUILD)/man/vmacd.1 $(BUILD)/man/vmac.1 $(BUILD)/man/vmac-board.1
MAN_NAME_vmacd      := the vmac control host: boards on the bus, a Lua driver for each
MAN_NAME_vmac       := the command line for vmac hosts and their drivers
MAN_NAME_vmac-board := vmac I/O boards with simulated plants, on POSIX

# The service's files name the Debian package's paths; other prefixes get theirs.
SERVICE_PATHS = -e 's|/usr/bin/vmacd|$(BINDIR)/vmacd|g' -e 's|/etc/vmac/|$(SYSCONFDIR)/vmac/|g' \
                -e 's|/usr/share/doc/vmac|$(DOCDIR)|g' -e 's|/usr/share/vmac|$(DATADIR)|g' \
                -e 's|/lib/systemd/system|$(UNITDIR)|g'

.PHONY: install uninstall deb test-package

$(BUILD)/man/%.1: $(BUILD)/bin/% packaging/see-also.h2m packaging/help2man-wrap.sh
	@mkdir -p $(dir $@)
	VMAC_H2M_PROGRAM=$< help2man --no-info --include=packaging/see-also.h2m --name="$(MAN_NAME_$*)" \
		--output=$@ packaging/help2man-wrap.sh

# The settings file is never written over: one changed by hand stays, and
# the shipped one is said.
install: $(BINS) $(MAN_PAGES)
	install -d $(DESTDIR)$(BINDIR) $(DESTDIR)$(DATADIR) $(DESTDIR)$(DOCDIR) $(DESTDIR)$(MAN1DIR) \
		$(DESTDIR)$(UNITDIR) $(DESTDIR)$(SYSUSERSDIR) $(DESTDIR)$(TMPFILESDIR) $(DESTDIR)$(SYSCONFDIR)/vmac
	install -m 0755 $(BINS) $(DESTDIR)$(BINDIR)/
	@for f in $(INSTALL_DATA); do install -D -m 0644 $$f $(DESTDIR)$(DATADIR)/$$f || exit 1; done
	@for f in $(INSTALL_TYPES); do install -D -m 0644 $$f $(DESTDIR)$(DATADIR)/types/$${f#scripts/types/} || exit 1; done
	install -m 0644 $(INSTALL_DOCS) $(DESTDIR)$(DOCDIR)/
	install -D -m 0644 docs/grafana/vmac-dashboard.json $(DESTDIR)$(DOCDIR)/grafana/vmac-dashboard.json
	install -m 0644 $(MAN_PAGES) $(DESTDIR)$(MAN1DIR)/
	sed $(SERVICE_PATHS) packaging/vmacd.service > $(DESTDIR)$(UNITDIR)/vmacd.service
	install -m 0644 packaging/vmac.sysusers $(DESTDIR)$(SYSUSERSDIR)/vmac.conf
	install -m 0644 packaging/vmac.tmpfiles $(DESTDIR)$(TMPFILESDIR)/vmac.conf
	@conf=$(DESTDIR)$(SYSCONFDIR)/vmac/vmacd.conf; \
	if [ -e $$conf ]; then sed $(SERVICE_PATHS) packaging/vmacd.conf > $$conf.dist; \
		echo "make install: kept $$conf; the shipped one is $$conf.dist"; \
	else sed $(SERVICE_PATHS) packaging/vmacd.conf > $$conf; fi
	@[ -n "$(DESTDIR)" ] || echo "make install: done. For the service, as root: systemd-sysusers;" \
		"systemd-tmpfiles --create vmac.conf; systemctl daemon-reload; systemctl enable --now vmacd" \
		"(docs/SERVICE.md)"

# Everything install put there but the settings file and the state.
uninstall:
	rm -f $(addprefix $(DESTDIR)$(BINDIR)/,vmacd vmac vmac-board) \
		$(addprefix $(DESTDIR)$(MAN1DIR)/,vmacd.1 vmac.1 vmac-board.1) \
		$(DESTDIR)$(UNITDIR)/vmacd.service $(DESTDIR)$(SYSUSERSDIR)/vmac.conf $(DESTDIR)$(TMPFILESDIR)/vmac.conf
	rm -rf $(DESTDIR)$(DATADIR) $(DESTDIR)$(DOCDIR)

# The package is built by Debian's tools in a copy of the tree (the files
# git knows, changed or new, none it ignores), so that dpkg-buildpackage
# writes nothing in the tree itself: the programs in the copy's
# debian/build (debian/rules), the .deb beside the copy in $(DEB_OUT).
# It runs apart from this make (none of its variables, BUILD included).
# debian/changelog must be at core/common/version.h's version.
DEB_OUT     := $(BUILD)/deb
DEB_VERSION := $(shell sed -n 's/^\#define VMAC_VERSION_STRING "\(.*\)"$$/\1/p' core/common/version.h)

# What make deb needs on a fresh machine, and only that: debian/control's
# Build-Depends and the tools that read it (not the whole of make deps).
DEB_BUILD_DEBS := build-essential dpkg-dev debhelper lintian help2man git pkg-config python3 libluajit-5.1-dev \
                  libev-dev libmicrohttpd-dev libjansson-dev libcurl4-openssl-dev libsqlite3-dev libsodium-dev \
                  libmosquitto-dev protobuf-c-compiler libprotobuf-c-dev libsystemd-dev

deb:
	@$(MAKE) --no-print-directory deps DEBS="$(DEB_BUILD_DEBS)"
	@said=$$(dpkg-parsechangelog -S Version); if [ "$$said" != "$(DEB_VERSION)" ]; then \
		echo "make deb: debian/changelog is at $$said, core/common/version.h at $(DEB_VERSION):" \
			"add a changelog entry (dch -v $(DEB_VERSION))"; exit 1; fi
	rm -rf $(DEB_OUT) && mkdir -p $(DEB_OUT)/src
	@if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then \
		git ls-files -z --cached --others --exclude-standard | \
			tar --null -T - --ignore-failed-read -cf - 2>/dev/null | tar -C $(DEB_OUT)/src -xf -; \
	else tar --exclude=./build --exclude=node_modules -cf - . | tar -C $(DEB_OUT)/src -xf -; fi
	cd $(DEB_OUT)/src && env -u MAKEFLAGS -u MFLAGS -u MAKELEVEL dpkg-buildpackage --build=binary --no-sign -jauto
	lintian --fail-on error,warning $(DEB_OUT)/vmac_$(DEB_VERSION)_*.deb
	@ls $(DEB_OUT)/*.deb

# Installs and purges the vmac package on this machine (root): a vmac
# installed before is purged first (docs/SERVICE.md, "Testing the package").
# Then the same package under a real systemd: a Debian root (mmdebstrap,
# kept in $(BUILD)/boot-root) booted with systemd-nspawn (tests/package/boot.py).
# The root is made while make deb builds (boot.py --prepare, for the
# libraries the programs of $(BUILD)/bin link: the package's own).
test-package: $(BINS)
	@python3 tests/package/boot.py --prepare --root $(BUILD)/boot-root --bins "$(BINS)" \
		> $(BUILD)/boot-prepare.log 2>&1 & prep=$$!; \
	VMAC_SKIP_FILE=$(SKIPPED) python3 tests/package/test_package.py --build $(BUILD); rc=$$?; \
	wait $$prep; cat $(BUILD)/boot-prepare.log; exit $$rc
	@VMAC_SKIP_FILE=$(SKIPPED) python3 tests/package/boot.py --root $(BUILD)/boot-root \
		--deb $$(ls $(BUILD)/deb/vmac_[0-9]*.deb)
