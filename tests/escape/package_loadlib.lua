-- package.loadlib: load a C library
-- expect: attempt to index global 'package'
package.loadlib('libc.so.6', 'system')
return { name = "package_loadlib", version = "1", io = { lamp = "do0" }, tick = function(dev) dev.out.lamp = true end }
