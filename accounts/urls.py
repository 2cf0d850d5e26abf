from django.urls import path

from accounts import views

app_name = "accounts"

urlpatterns = [
    path("profile/", views.profile, name="profile"),
    path("profile/tokens/", views.token_new, name="token-new"),
    path("profile/tokens/<int:token_id>/revoke/", views.token_revoked, name="token-revoke"),
    path("email/confirm/<str:token>/", views.email_confirm, name="email-confirm"),
]
