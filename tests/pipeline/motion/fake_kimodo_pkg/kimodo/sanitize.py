"""Kimodo's prompt sanitisation, transcribed rule by rule from its sanitize_text (a separate
transcription from the adapter's, so the test that compares them can fail)."""


def sanitize_text(text: str) -> str:
    text = " ".join(text.strip().split())
    if text == "":
        return text
    i = 0
    while i < len(text) - 1 and not text[i].isalnum():
        i += 1
    text = text[i:].capitalize()
    j = len(text) - 1
    while j > 0 and not (text[j].isalnum() or text[j] in ".!?\"])'"):
        j -= 1
    text = text[: j + 1]
    if text[-1] not in ".!?":
        text = text + "."
    for brk in ".!?":
        pieces = []
        for piece in text.split(brk):
            piece = piece.strip()
            pieces.append(piece[0].capitalize() + piece[1:] if piece else piece)
        text = f"{brk} ".join(pieces).strip()
    return text


def sanitize_texts(texts):
    return [sanitize_text(text) for text in texts]
