# Build, install and test the LinuxCNC side of nurbs-motion.
#
#   make               realtime module nurbs_interp.so + userspace planner (needs linuxcnc-uspace-dev)
#                      + the offline CLI nurbs-plan (the tests compare against it)
#   make install       module into $(MODULE_DIR), planner, recorder, nurbs-plan and the program
#                      filter nurbs-filter into $(BINDIR), examples and configs/nurbs-sim into $(DATADIR)
#   make test          cargo test (mock HAL) + the real-LinuxCNC tests in tests/hal/
#   make bench         criterion: per-period cost of nurbs_interp.update (mock HAL)
#   make man           docs/man/nurbs_interp.9 and the pin table of docs/integration.md from the
#                      module's pin declarations, docs/man/nurbs-plan.1 and nurbs-planner.1 from
#                      the command lines, the preset table of docs/planners.md from the presets
#                      (committed; the tests check them)
#   make headers       cbindgen -> include/nurbs_rt.h   (committed)
#   make bindings      bindgen  -> hal/src/bindings.rs (committed; a normal build needs no libclang)
#   make check-generated   fail if the committed header or bindings are stale
#   make tools         install the generator versions the committed files were made with
#
# The module is this workspace's nurbs-interp staticlib (hal/module: the no_std nurbs-hal crate,
# aborting on panic) linked whole into a shared object. Only the RTAPI entry points are exported
# (hal/module.ver) and -Bsymbolic binds our own references inside the module, so two Rust modules
# loaded into the same rtapi_app never share globals. hal_* resolve from hal_lib.so and rtapi_*
# from rtapi_app at dlopen time: never link liblinuxcnchal into the module. The userspace
# binaries (nurbs-planner, nurbs-hal-record) come from the planner/ crate.

CARGO       ?= cargo
CC          ?= gcc
BINDGEN     ?= bindgen
CBINDGEN    ?= cbindgen
TARGET_DIR  ?= $(or $(CARGO_TARGET_DIR),target)
OUT         := $(TARGET_DIR)/release
MODULE      := $(OUT)/nurbs_interp.so
STATICLIB   := $(OUT)/libnurbs_interp.a
BINS        := nurbs-planner nurbs-hal-record nurbs-plan
LINUXCNC_INCLUDE ?= /usr/include/linuxcnc
MODULE_DIR  ?= /usr/lib/linuxcnc/modules
PREFIX      ?= /usr/local
BINDIR      ?= $(PREFIX)/bin
# Examples (the toolpaths a configuration names are looked up here too) and the sample
# configuration, to copy into a user's folder. M101 also looks in /usr/share/nurbs-motion and in
# $$NURBS_MOTION_DATA: with another PREFIX set that variable.
DATADIR     ?= $(PREFIX)/share/nurbs-motion
MANDIR      ?= $(PREFIX)/share/man
# Generator versions: their output is committed, so every machine must produce the same bytes.
# bindgen from Debian bookworm (with its libclang); cbindgen from crates.io (Debian's 0.24 cannot
# parse C-string literals or let-else).
BINDGEN_VERSION  := 0.60.1
CBINDGEN_VERSION := 0.29.4

# What the no_std staticlib needs from the C side (abort, memcpy and friends).
NATIVE_LIBS := -lc

BINDGEN_FLAGS := --use-core --ctypes-prefix core::ffi --no-layout-tests --no-doc-comments \
	--default-enum-style=consts \
	--raw-line '\#![allow(non_camel_case_types, non_upper_case_globals, non_snake_case, dead_code)]' \
	--allowlist-function 'hal_(init|ready|exit|malloc)' \
	--allowlist-function 'hal_pin_(bit|float|u32|s32)_new' \
	--allowlist-function 'hal_param_(bit|float|u32|s32)_new' \
	--allowlist-function 'hal_export_funct' \
	--allowlist-function 'hal_stream_.*' \
	--allowlist-function 'rtapi_(print_msg|shmem_new|shmem_delete|shmem_getptr|get_clocks|get_time)' \
	--allowlist-var 'HAL_NAME_LEN|HAL_STREAM_MAX_PINS|RTAPI_NAME_LEN'

.PHONY: all module planner install uninstall test test-cargo test-hal bench headers bindings \
	check-generated tools clean man FORCE

all: module planner

# The module's staticlib and the userspace binaries are separate cargo invocations: the module
# must not share features (the mock HAL, std) with anything else.
$(STATICLIB): FORCE
	$(CARGO) build --release --manifest-path hal/module/Cargo.toml --target-dir $(TARGET_DIR)

planner: FORCE
	$(CARGO) build --release -p nurbs-planner --features linuxcnc --bins
	$(CARGO) build --release -p nurbs-cli --bin nurbs-plan

module: $(MODULE)

$(MODULE): $(STATICLIB) hal/module.ver
	$(CC) -shared -o $@ -Wl,--whole-archive $(STATICLIB) -Wl,--no-whole-archive \
		-Wl,-Bsymbolic -Wl,--version-script=hal/module.ver -Wl,--gc-sections $(NATIVE_LIBS)

install: all
	install -d $(DESTDIR)$(MODULE_DIR) $(DESTDIR)$(BINDIR) $(DESTDIR)$(MANDIR)/man9 $(DESTDIR)$(MANDIR)/man1
	install -m 0644 $(MODULE) $(DESTDIR)$(MODULE_DIR)/nurbs_interp.so
	install -m 0644 docs/man/nurbs_interp.9 $(DESTDIR)$(MANDIR)/man9/nurbs_interp.9
	install -m 0644 docs/man/nurbs-plan.1 docs/man/nurbs-planner.1 $(DESTDIR)$(MANDIR)/man1/
	for b in $(BINS); do install -m 0755 $(OUT)/$$b $(DESTDIR)$(BINDIR)/$$b; done
	install -m 0755 linuxcnc/nurbs-filter $(DESTDIR)$(BINDIR)/nurbs-filter
	rm -rf $(DESTDIR)$(DATADIR)/examples $(DESTDIR)$(DATADIR)/configs
	install -d $(DESTDIR)$(DATADIR)/examples $(DESTDIR)$(DATADIR)/configs
	cp -r examples/. $(DESTDIR)$(DATADIR)/examples/
	cp -r configs/nurbs-sim $(DESTDIR)$(DATADIR)/configs/

uninstall:
	rm -f $(DESTDIR)$(MODULE_DIR)/nurbs_interp.so $(DESTDIR)$(MANDIR)/man9/nurbs_interp.9
	rm -f $(DESTDIR)$(MANDIR)/man1/nurbs-plan.1 $(DESTDIR)$(MANDIR)/man1/nurbs-planner.1
	for b in $(BINS); do rm -f $(DESTDIR)$(BINDIR)/$$b; done
	rm -f $(DESTDIR)$(BINDIR)/nurbs-filter
	rm -rf $(DESTDIR)$(DATADIR)

test: test-cargo test-hal

test-cargo:
	$(CARGO) test --workspace

bench:
	$(CARGO) bench -p nurbs-planner --bench update

# Needs root (or the RTAPI_UID setup in tests/hal/lib.sh) and an installed module.
test-hal: install
	bash tests/hal/run.sh

man:
	UPDATE_DOCS=1 $(CARGO) test -p nurbs-planner --test pins_doc
	UPDATE_DOCS=1 $(CARGO) test -p nurbs-cli --test man
	UPDATE_DOCS=1 $(CARGO) test -p nurbs-motion --test docs

headers: include/nurbs_rt.h

include/nurbs_rt.h: FORCE
	@$(CBINDGEN) --version | grep -q ' $(CBINDGEN_VERSION)$$' || \
		{ echo "need cbindgen $(CBINDGEN_VERSION) (make tools)"; exit 1; }
	$(CBINDGEN) --quiet --config hal/cbindgen.toml --crate nurbs-hal --output $@ hal

bindings: hal/src/bindings.rs

hal/src/bindings.rs: FORCE
	@$(BINDGEN) --version | grep -q ' $(BINDGEN_VERSION)$$' || \
		{ echo "need bindgen $(BINDGEN_VERSION) (make tools)"; exit 1; }
	$(BINDGEN) hal/wrapper.h $(BINDGEN_FLAGS) --rustfmt-configuration-file $(CURDIR)/hal/bindings-rustfmt.toml \
		-o $@ -- -I$(LINUXCNC_INCLUDE) -DRTAPI -DUSPACE

check-generated:
	@tmp=$$(mktemp -d) && trap 'rm -rf "$$tmp"' EXIT && \
	cp include/nurbs_rt.h hal/src/bindings.rs "$$tmp"/ && \
	$(MAKE) --no-print-directory headers bindings >/dev/null && \
	stale=0 && \
	{ cmp -s "$$tmp"/nurbs_rt.h include/nurbs_rt.h || { echo "include/nurbs_rt.h is stale: run make headers"; stale=1; }; } && \
	{ cmp -s "$$tmp"/bindings.rs hal/src/bindings.rs || { echo "hal/src/bindings.rs is stale: run make bindings"; stale=1; }; } && \
	if [ $$stale = 1 ]; then \
		git --no-pager diff --no-index "$$tmp"/nurbs_rt.h include/nurbs_rt.h || true; \
		git --no-pager diff --no-index "$$tmp"/bindings.rs hal/src/bindings.rs || true; \
		cp "$$tmp"/nurbs_rt.h include/nurbs_rt.h; cp "$$tmp"/bindings.rs hal/src/bindings.rs; exit 1; \
	fi; echo "generated files are up to date"

tools:
	apt-get install -y --no-install-recommends bindgen=$(BINDGEN_VERSION)-\* libclang-dev
	$(CBINDGEN) --version 2>/dev/null | grep -q ' $(CBINDGEN_VERSION)$$' || \
		$(CARGO) install --locked cbindgen --version $(CBINDGEN_VERSION)

clean:
	$(CARGO) clean -p nurbs-hal -p nurbs-planner
	rm -f $(MODULE)

FORCE:

# ---------------------------------------------------------------------------------------------
# The README's two commands: `make demo` (set up, plan the bundled butterfly offline and verify
# it, then run it through our module and planner in real LinuxCNC and check every sampled period)
# and `make check` (set up, lint, every test including real LinuxCNC). CI runs `make check`.
DEMO_LIMITS := --feed 2500 --accel 1e4 --jerk 6e4 --chord-tol 0.001 --period 0.00025

.PHONY: setup demo check lint

setup:
	bash .ci/setup.sh

demo: setup install
	mkdir -p out
	$(OUT)/nurbs-plan inspect examples/butterfly.json
	$(OUT)/nurbs-plan plan examples/butterfly.json $(DEMO_LIMITS) --out out/butterfly.csv --summary out/butterfly.json
	$(OUT)/nurbs-plan verify out/butterfly.csv examples/butterfly.json $(DEMO_LIMITS)
	cat out/butterfly.json
	bash tests/hal/test_butterfly.sh

lint:
	$(CARGO) fmt --all -- --check
	$(CARGO) fmt --manifest-path hal/module/Cargo.toml -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings
	$(CARGO) clippy --manifest-path hal/module/Cargo.toml --target-dir $(TARGET_DIR) -- -D warnings

check: setup lint check-generated
	$(CARGO) test --workspace
	$(MAKE) --no-print-directory test-hal
