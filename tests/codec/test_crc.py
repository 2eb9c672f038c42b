from ktcs_bench.codec.crc import CHECK_INPUT, crc16_arc, crc_extension_in_use


def test_crc16_arc_check_value() -> None:
    assert crc16_arc(CHECK_INPUT) == 0xBB3D


def test_fig7_crc_and_residue() -> None:
    head = bytes.fromhex("020400100000")
    assert crc16_arc(head) == 0xE7F1
    # the console's "Cal = [00]-[00]": the CRC run over the data and its CRC (low byte first)
    assert crc16_arc(head + bytes.fromhex("F1E7")) == 0x0000


def test_crcmod_uses_its_c_extension() -> None:
    assert crc_extension_in_use(), "crcmod fell back to pure Python (its C extension is missing)"
