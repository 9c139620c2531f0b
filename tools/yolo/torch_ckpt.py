"""Read a PyTorch zip checkpoint (torch.save, protocol 2 pickle) without torch.

The checkpoint is a zip: `<prefix>/data.pkl` is a pickle whose tensors refer to
raw storages `<prefix>/data/<key>` through persistent ids. Unpickling runs code
named inside the file, so only a fixed set of globals is resolved: tensor
rebuilders, storage types, plain containers, and stand-ins for nn.Module classes
(those are never imported; each becomes an attribute bag keeping its class name).
"""

import collections
import pickle
import zipfile

import numpy as np

# torch storage class -> numpy dtype (little-endian, as torch writes it).
_STORAGE_DTYPES = {
    "HalfStorage": np.float16,
    "FloatStorage": np.float32,
    "DoubleStorage": np.float64,
    "BFloat16Storage": None,  # no numpy dtype; rejected below if ever used
    "LongStorage": np.int64,
    "IntStorage": np.int32,
    "ShortStorage": np.int16,
    "CharStorage": np.int8,
    "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}

# Module classes a YOLOv5/YOLOv7 segmentation checkpoint pickles. Anything else
# is refused so a different or hostile file fails loudly instead of silently.
_MODULE_PREFIXES = ("models.common", "models.yolo", "models.experimental", "torch.nn.modules.")


class Module:
    """Attribute bag standing in for an nn.Module; `cls` is the pickled class path."""

    cls = "?"

    def children(self):
        return self.__dict__.get("_modules", {})

    def __getattr__(self, name):
        # nn.Module keeps parameters, buffers and submodules in side dicts.
        for store in ("_parameters", "_buffers", "_modules"):
            d = self.__dict__.get(store)
            if d is not None and name in d:
                return d[name]
        raise AttributeError(f"{self.cls} has no attribute {name!r}")

    def __repr__(self):
        return f"<{self.cls}>"


class _StorageType:
    def __init__(self, name):
        if _STORAGE_DTYPES.get(name) is None:
            raise pickle.UnpicklingError(f"unsupported storage type {name}")
        self.name = name
        self.dtype = np.dtype(_STORAGE_DTYPES[name]).newbyteorder("<")


class _Unresolved:
    """Result of a pickled getattr(cls, name): recorded, never evaluated."""

    def __init__(self, obj, name):
        self.obj, self.name = obj, name

    def __repr__(self):
        return f"<getattr {self.obj!r}.{self.name}>"


def _rebuild_tensor_v2(storage, offset, size, stride, requires_grad=False, hooks=None, metadata=None):
    item = storage.dtype.itemsize
    if len(size) == 0:
        return storage[offset].copy()
    view = np.lib.stride_tricks.as_strided(
        storage[offset:], shape=tuple(size), strides=tuple(s * item for s in stride)
    )
    return np.ascontiguousarray(view)


def _rebuild_parameter(data, requires_grad=False, hooks=None):
    return data


class _Unpickler(pickle.Unpickler):
    def __init__(self, file, zf, prefix):
        super().__init__(file)
        self._zf, self._prefix, self._storages = zf, prefix, {}
        self._module_classes = {}

    def find_class(self, module, name):
        full = f"{module}.{name}"
        if full == "collections.OrderedDict":
            return collections.OrderedDict
        if full in ("__builtin__.set", "builtins.set"):
            return set
        if full in ("__builtin__.getattr", "builtins.getattr"):
            return _Unresolved
        if full == "torch._utils._rebuild_tensor_v2":
            return _rebuild_tensor_v2
        if full == "torch._utils._rebuild_parameter":
            return _rebuild_parameter
        if module == "torch" and name in _STORAGE_DTYPES:
            return _StorageType(name)
        if module.startswith(_MODULE_PREFIXES):
            if full not in self._module_classes:
                self._module_classes[full] = type(name, (Module,), {"cls": full})
            return self._module_classes[full]
        raise pickle.UnpicklingError(f"refusing to load global {full}")

    def persistent_load(self, pid):
        # ('storage', storage_type, key, location, numel)
        if not (isinstance(pid, tuple) and pid and pid[0] == "storage"):
            raise pickle.UnpicklingError(f"unexpected persistent id {pid!r}")
        _, stype, key, _location, numel = pid
        if key not in self._storages:
            raw = self._zf.read(f"{self._prefix}/data/{key}")
            arr = np.frombuffer(raw, dtype=stype.dtype)
            if arr.size != numel:
                raise pickle.UnpicklingError(f"storage {key}: {arr.size} elements, expected {numel}")
            self._storages[key] = arr
        return self._storages[key]


def load(path):
    """Return the checkpoint's top-level object with tensors as numpy arrays."""
    with zipfile.ZipFile(path) as zf:
        pkl = [n for n in zf.namelist() if n.endswith("/data.pkl")]
        if len(pkl) != 1:
            raise ValueError(f"{path}: not a torch zip checkpoint")
        prefix = pkl[0][: -len("/data.pkl")]
        bo = f"{prefix}/byteorder"
        if bo in zf.namelist() and zf.read(bo).strip() != b"little":
            raise ValueError(f"{path}: big-endian checkpoint")
        with zf.open(pkl[0]) as f:
            return _Unpickler(f, zf, prefix).load()
