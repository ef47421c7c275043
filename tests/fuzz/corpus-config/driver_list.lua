driver = { [1] = {} }
